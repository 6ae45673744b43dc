//! **Uncertainty** of the pose estimate (paper V.D, last paragraph): for one tactile signature, N samples of the
//! in-contact depth from the model, each registered from one fixed initialisation; the distribution of their position
//! and θ errors as Gaussian KDEs ([`kde`], Scott's rule), with the baseline's errors as points; exported as CSV and a
//! PNG plot ([`plot`]).

pub mod kde;

pub use kde::{GaussianKde, KdeError};
