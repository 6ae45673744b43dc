//! **Gaussian kernel density estimate** (paper V.D, uncertainty): the distribution of pose errors over model samples,
//! exactly as `scipy.stats.gaussian_kde(data)` with its default bandwidth (Scott's rule):
//!
//! * kernel covariance `Σ = cov(data) · f²`, with `cov` the unbiased sample covariance (ddof = 1) and Scott's factor
//!   `f = n^(−1/(d+4))`;
//! * `p(x) = (1/n) Σᵢ N(x; xᵢ, Σ)`.

use serde::{Deserialize, Serialize};

/// Errors building a KDE.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum KdeError {
    #[error("a KDE needs at least 2 points (got {0})")]
    TooFew(usize),
    #[error("all points must have {expected} coordinates; point {index} has {got}")]
    Dimension {
        expected: usize,
        index: usize,
        got: usize,
    },
    #[error("point {0} has a non-finite coordinate")]
    NonFinite(usize),
    #[error("the points' covariance is singular (all samples equal or collinear); no density can be estimated")]
    Singular,
}

/// A Gaussian KDE over `d`-dimensional points.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaussianKde {
    points: Vec<Vec<f64>>,
    /// Lower-triangular Cholesky factor of the kernel covariance, row-major d x d.
    chol: Vec<f64>,
    /// 1 / (n · sqrt((2π)^d det Σ)).
    norm: f64,
    /// Scott's factor used.
    factor: f64,
    dim: usize,
}

impl GaussianKde {
    /// Fit with Scott's rule (see the module docs).
    pub fn scott(points: &[Vec<f64>]) -> Result<Self, KdeError> {
        let n = points.len();
        if n < 2 {
            return Err(KdeError::TooFew(n));
        }
        let d = points[0].len();
        for (index, p) in points.iter().enumerate() {
            if p.len() != d || d == 0 {
                return Err(KdeError::Dimension {
                    expected: d,
                    index,
                    got: p.len(),
                });
            }
            if p.iter().any(|x| !x.is_finite()) {
                return Err(KdeError::NonFinite(index));
            }
        }
        let mean: Vec<f64> = (0..d)
            .map(|k| points.iter().map(|p| p[k]).sum::<f64>() / n as f64)
            .collect();
        let factor = (n as f64).powf(-1.0 / (d as f64 + 4.0));
        let mut cov = vec![0.0; d * d];
        for p in points {
            for i in 0..d {
                for j in 0..d {
                    cov[i * d + j] += (p[i] - mean[i]) * (p[j] - mean[j]);
                }
            }
        }
        for c in &mut cov {
            *c *= factor * factor / (n as f64 - 1.0);
        }
        let chol = cholesky(&cov, d).ok_or(KdeError::Singular)?;
        let det_sqrt: f64 = (0..d).map(|i| chol[i * d + i]).product();
        let norm = 1.0 / (n as f64 * (std::f64::consts::TAU).powf(d as f64 / 2.0) * det_sqrt);
        Ok(Self {
            points: points.to_vec(),
            chol,
            norm,
            factor,
            dim: d,
        })
    }

    /// Fit a 1-D KDE.
    pub fn scott_1d(values: &[f64]) -> Result<Self, KdeError> {
        let pts: Vec<Vec<f64>> = values.iter().map(|&v| vec![v]).collect();
        Self::scott(&pts)
    }

    /// Scott's factor `n^(−1/(d+4))`.
    pub fn factor(&self) -> f64 {
        self.factor
    }

    /// Kernel standard deviation of a 1-D KDE (the square root of the kernel variance; for d > 1, of the first axis).
    pub fn bandwidth(&self) -> f64 {
        self.chol[0]
    }

    /// Density at `x` (d coordinates).
    pub fn density(&self, x: &[f64]) -> f64 {
        let d = self.dim;
        let mut diff = vec![0.0; d];
        let mut z = vec![0.0; d];
        let mut sum = 0.0;
        for p in &self.points {
            for k in 0..d {
                diff[k] = x.get(k).copied().unwrap_or(f64::NAN) - p[k];
            }
            // Solve L z = diff; the Mahalanobis distance is |z|².
            for i in 0..d {
                let row = &self.chol[i * d..i * d + i];
                let s = diff[i] - row.iter().zip(&z[..i]).map(|(l, zj)| l * zj).sum::<f64>();
                z[i] = s / self.chol[i * d + i];
            }
            sum += (-0.5 * z.iter().map(|v| v * v).sum::<f64>()).exp();
        }
        sum * self.norm
    }
}

/// Cholesky factor of a symmetric positive-definite d x d matrix; `None` if it is not.
fn cholesky(a: &[f64], d: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let mut s = a[i * d + j];
            for k in 0..j {
                s -= l[i * d + k] * l[j * d + k];
            }
            if i == j {
                if s.is_nan() || s <= 1e-300 {
                    return None;
                }
                l[i * d + i] = s.sqrt();
            } else {
                l[i * d + j] = s / l[j * d + j];
            }
        }
    }
    Some(l)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_dimensional_kde_is_a_normalised_mixture() {
        let kde = GaussianKde::scott_1d(&[0.0, 1.0, 2.0, 4.0]).unwrap();
        // Integrates to one.
        let integral: f64 = (-12000..16000)
            .map(|i| kde.density(&[i as f64 * 0.001]) * 0.001)
            .sum();
        assert!((integral - 1.0).abs() < 1e-6, "{integral}");
        assert!((kde.factor() - 4f64.powf(-0.2)).abs() < 1e-15);
        assert!(GaussianKde::scott_1d(&[1.0]).is_err());
        assert_eq!(
            GaussianKde::scott_1d(&[2.0, 2.0]).unwrap_err(),
            KdeError::Singular
        );
    }
}
