//! Small dense linear algebra over (x, y, θ) for the pose posterior ([`super::posterior`]): 3x3 symmetric
//! eigen-decomposition and Cholesky factors, projections onto the coordinates a symmetry leaves identifiable, and
//! Gaussian log densities.

/// A 3x3 matrix, row-major, over (x m, y m, θ rad).
pub type Mat3 = [[f64; 3]; 3];

/// Copy the lower triangle of `m` onto its upper one: a symmetric matrix, exactly.
pub(crate) fn mirror_lower(m: &mut Mat3) {
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        m[i][j] = m[j][i];
    }
}

/// Eigenvalues and eigenvectors (columns) of a symmetric 3x3 matrix, by cyclic Jacobi rotations.
pub fn symmetric_eigen3(a: &Mat3) -> ([f64; 3], Mat3) {
    let mut a = *a;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let scale = (0..3).map(|i| a[i][i].powi(2)).sum::<f64>();
        if off <= 1e-30 * scale.max(1e-300) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * row_p[k] - s * row_q[k];
                a[q][k] = s * row_p[k] + c * row_q[k];
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}

/// Lower Cholesky factor of a symmetric positive definite 3x3 matrix; `None` when it is not.
pub(crate) fn cholesky3(a: &Mat3) -> Option<Mat3> {
    let mut l = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let s: f64 = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    Some(l)
}

/// `rows · cov · rowsᵀ`.
pub(crate) fn project(cov: &Mat3, rows: &[[f64; 3]]) -> Vec<Vec<f64>> {
    rows.iter()
        .map(|r| {
            rows.iter()
                .map(|q| {
                    (0..3)
                        .map(|i| (0..3).map(|j| r[i] * cov[i][j] * q[j]).sum::<f64>())
                        .sum()
                })
                .collect()
        })
        .collect()
}

/// log N(e; 0, c) for a k-dimensional `e` (k ≤ 3); −∞ when `c` is not positive definite.
pub(crate) fn gaussian_log_density(e: &[f64], c: &[Vec<f64>]) -> f64 {
    let k = e.len();
    let mut full = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for i in 0..k {
        for j in 0..k {
            full[i][j] = c[i][j];
        }
    }
    let Some(l) = cholesky3(&full) else {
        return f64::NEG_INFINITY;
    };
    // Solve L y = e; the quadratic form is |y|², log det = 2 Σ ln L_ii.
    let mut y = [0.0; 3];
    for i in 0..k {
        y[i] = (e[i] - (0..i).map(|j| l[i][j] * y[j]).sum::<f64>()) / l[i][i];
    }
    let quad: f64 = y[..k].iter().map(|v| v * v).sum();
    let log_det: f64 = (0..k).map(|i| 2.0 * l[i][i].ln()).sum();
    -0.5 * (quad + log_det + k as f64 * (std::f64::consts::TAU).ln())
}

pub(crate) fn log_sum_exp(terms: &[f64]) -> f64 {
    let max = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return max;
    }
    max + terms.iter().map(|t| (t - max).exp()).sum::<f64>().ln()
}
