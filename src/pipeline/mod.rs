//! # Use cases: one pipeline, two front ends
//!
//! The steps a user runs, each as one function over one config struct, shared by the command line (`tnd`) and the
//! workbench so that both do exactly the same work for the same settings (a test checks that their samples and poses
//! are bit-identical):
//!
//! | use case | config | entry point |
//! |---|---|---|
//! | load the object a user names | [`ObjectSpec`] | [`ObjectSpec::load`] |
//! | de-render: N samples of X0 for one imprint | [`DerenderConfig`] | [`derender()`] |
//! | estimate the pose from the samples (one and many) | a [`crate::pose::Estimator`] (its [`crate::pose::PoseConfig`]) + seed | [`estimate_observation`] (the one sequence), [`estimate_pose`], [`place_and_estimate`] |
//! | its record, pose.json | [`pose_record::RecordSource`] | [`pose_record::PoseRecord::new`], [`pose_record::PoseRecord::write`] |
//! | export its geometry for Open3D / trimesh (PLY) | [`crate::io::ply::PlyEncoding`] | [`write_pose_geometry`] |
//! | draw its figures (KDE, SE(2) fits; SVG + PNG) | [`crate::io::figure::FigureConfig`] | [`write_fit_figure`], [`crate::uncertainty::UncertaintyReport::write_with`] |
//! | simulate a press | [`crate::sim::SimConfig`] | [`crate::sim::Simulator::simulate`] |
//! | generate a dataset | [`crate::dataset::GenConfig`] | [`crate::dataset::gen::generate`] |
//! | train | [`crate::model::train::TrainConfig`] | [`crate::model::train::train`] |
//! | evaluate (the same pose sequence on every pair) | [`crate::metrics::evaluate::EvalConfig`] | [`evaluate::Evaluator::evaluate`] |
//! | place the sensor: find how far it is pressed | [`press::PressChoice`] | [`press::SensorPlacement::press`] |
//! | estimate the pose on every contact frame of a recording | [`track::TrackContext`], [`track::TrackingConfig`] | [`track::Tracker::track`] |
//! | calibrate the inflation | a [`crate::sim::SimConfig`] and the inflations | [`crate::sim::calibration::sweep_inflation`] |
//!
//! Configs are serde (the workbench stores them in its session) and `clap::Args` (the CLI flattens them), with
//! their defaults defined once. Long use cases take a [`Progress`] callback: it is told `(done, total)` after each
//! step and returning `false` cancels the run ([`PipelineError::Cancelled`]).
//!
//! Layering: `pipeline` calls the stages (`mesh`, `objects`, `sim`, `model`, `pose`, `metrics`, `uncertainty`);
//! no stage calls back up into it, and it never prints, draws or reads the environment.

pub mod derender;
pub mod evaluate;
pub mod object;
pub mod pose;
pub mod pose_record;
pub mod press;
pub mod track;
pub mod track_posteriors;
pub mod tracker;

pub use derender::{derender, imprint_guidance, mean_std, DerenderConfig, Derendered};
pub use object::{LoadedObject, ObjectSpec};
pub use pose::{
    estimate_observation, estimate_pose, place_and_estimate, pose_stage, pose_steps,
    write_fit_figure, write_pose_geometry, Observation, PlacedEstimate, Placement, PoseEstimate,
    PoseInput,
};

use std::path::PathBuf;

/// Progress of a long use case: called with `(done, total)` after each step; returning `false` cancels it.
pub type Progress<'a> = &'a mut dyn FnMut(usize, usize) -> bool;

/// Errors of the use cases: the stage's own error (kept as the source, said once by [`crate::error::render`]) or
/// what the use case itself checks.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Mesh(#[from] crate::mesh::MeshError),
    #[error(transparent)]
    Object(#[from] crate::objects::ObjectError),
    #[error(transparent)]
    Sim(#[from] crate::sim::SimError),
    #[error(transparent)]
    Model(#[from] crate::model::ModelError),
    #[error(transparent)]
    Pose(#[from] crate::pose::PoseError),
    #[error(transparent)]
    Eval(#[from] crate::metrics::evaluate::EvalError),
    #[error("unknown object '{name}': not in the {set} set ({known}) and not a mesh file")]
    UnknownObject {
        name: String,
        set: String,
        known: String,
    },
    #[error("{}: the model works at {model_w}x{model_h} pixels but the imprint is {w}x{h} (set the sensor resolution to {model_w}x{model_h} or use a model trained at this resolution)", model.display())]
    Resolution {
        model: PathBuf,
        model_w: usize,
        model_h: usize,
        w: usize,
        h: usize,
    },
    #[error("settings: {0}")]
    Settings(#[from] crate::error::InvalidSetting),
    /// An object whose size says its units are wrong ([`object::LoadedObject::check_scale`]).
    #[error("{0}")]
    Scale(String),
    #[error("{}: cannot write: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: {problem}", path.display())]
    Format { path: PathBuf, problem: String },
    #[error(transparent)]
    Figure(#[from] crate::io::figure::FigureError),
    #[error(transparent)]
    Uncertainty(#[from] crate::uncertainty::UncertaintyError),
    #[error("no sample has any contact; nothing to register")]
    NoContact,
    #[error("cancelled")]
    Cancelled,
}
