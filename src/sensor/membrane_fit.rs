//! **Membrane fit**: the parametric membrane (a half-ellipsoid of semi-axes `a`, `b` and height `h` on the sensor
//! base, [`super::ElastomerConfig`]) and the camera's position behind it, fitted to a measured no-contact depth image
//! of the membrane (the reference R). This is how a real sensor's inflation, footprint and camera offset are
//! calibrated ([`crate::recording::calibrate`] builds R from a recording's no-contact frames).
//!
//! A pixel with unit-z ray `d_cam` (camera frame) and measured z-depth `t` sees the sensor-frame point
//! `p = o + t d`, `d = R_sensor_camera d_cam`, `o` the camera's optical centre. On the membrane
//! `(p_x/a)^2 + (p_y/b)^2 + (p_z/h)^2 = 1`; multiplied by `h^2` this is **linear** in
//! `(A, B, A o_x, B o_y, o_z, A o_x^2 + B o_y^2 + o_z^2 - h^2)` with `A = (h/a)^2`, `B = (h/b)^2`, so an algebraic least
//! squares fit needs no starting point. It is then refined on the geometric residual (measured minus predicted depth
//! along each ray) by Gauss-Newton with Huber weights, which also gives each parameter's standard error.
//! The camera's rotation is not fitted: it is taken from the configuration.

use glam::{DAffine3, DVec3};
use serde::{Deserialize, Serialize};

use super::Intrinsics;
use crate::image::Image;

/// Errors of a membrane fit; each says what was wrong with the measurement.
#[derive(Debug, thiserror::Error)]
pub enum MembraneFitError {
    #[error(
        "the reference is {got_w}x{got_h} but the camera's intrinsics are {want_w}x{want_h}; fit at the resolution \
         the intrinsics describe"
    )]
    Size {
        got_w: usize,
        got_h: usize,
        want_w: usize,
        want_h: usize,
    },
    #[error(
        "only {0} pixels of the reference hold a depth; the membrane fit needs at least 50 (is the camera seeing the \
         membrane?)"
    )]
    TooFewPixels(usize),
    #[error(
        "the reference is not a dome seen from inside (the fitted surface is {0}); is it a depth image of the \
         membrane, in metres?"
    )]
    NotADome(&'static str),
}

/// Which parameters the fit may change; the others keep the starting values.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MembraneFitConfig {
    /// Fit the footprint (semi-axes a, b); default false. The camera sees only the middle of the dome, where a wider
    /// footprint and a camera further back change the depth image almost alike; the footprint is set by the
    /// sensor's clamping ring while inflation drifts, so by default it is held and the inflation comes out sharp.
    pub footprint: bool,
    /// Fit the camera's position behind the membrane (x, y, z); default true.
    pub camera_position: bool,
    /// Huber threshold of the robust refinement, in robust standard deviations of the residual (default 2.5).
    pub huber_k: f64,
    /// Gauss-Newton iterations at most (default 30).
    pub iterations: usize,
}

impl Default for MembraneFitConfig {
    fn default() -> Self {
        Self {
            footprint: false,
            camera_position: true,
            huber_k: 2.5,
            iterations: 30,
        }
    }
}

/// The membrane and camera position: the parameters of the fit, metres, sensor frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MembraneParams {
    /// Footprint length (x) and width (y): twice the semi-axes.
    pub footprint_m: [f64; 2],
    /// Height of the dome's apex above the base.
    pub inflation_m: f64,
    /// The camera's optical centre.
    pub camera_position_m: [f64; 3],
}

impl MembraneParams {
    fn to_vec(self) -> [f64; 6] {
        let [fx, fy] = self.footprint_m;
        let [cx, cy, cz] = self.camera_position_m;
        [fx / 2.0, fy / 2.0, self.inflation_m, cx, cy, cz]
    }

    fn from_vec(v: &[f64; 6]) -> Self {
        Self {
            footprint_m: [2.0 * v[0], 2.0 * v[1]],
            inflation_m: v[2],
            camera_position_m: [v[3], v[4], v[5]],
        }
    }
}

/// The result of a fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MembraneFit {
    pub params: MembraneParams,
    /// One standard error of each parameter (same layout; 0 for parameters held fixed), from the residual's spread
    /// and the fit's Jacobian: what the measurement's noise leaves uncertain, not the model's error.
    pub std_error: MembraneParams,
    /// Root mean square of measured minus fitted depth over the pixels used, metres.
    pub residual_rms_m: f64,
    /// Largest absolute residual, metres.
    pub residual_max_m: f64,
    /// Pixels with a depth (and a ray that meets the fitted membrane).
    pub pixels: usize,
    /// Gauss-Newton iterations run.
    pub iterations: usize,
}

/// The z-depth (camera frame) at which the ray `d` (sensor frame, from `o`) leaves the half-ellipsoid of `p`
/// (semi-axes a, b, h); `None` when it misses or leaves below the base.
fn depth_along(v: &[f64; 6], d: DVec3) -> Option<f64> {
    let [a, b, h, ox, oy, oz] = *v;
    let (px, py, pz) = (ox / a, oy / b, oz / h);
    let (dx, dy, dz) = (d.x / a, d.y / b, d.z / h);
    let qa = dx * dx + dy * dy + dz * dz;
    let qb = px * dx + py * dy + pz * dz;
    let qc = px * px + py * py + pz * pz - 1.0;
    let disc = qb * qb - qa * qc;
    if disc < 0.0 || qa <= 0.0 {
        return None;
    }
    let t = (-qb + disc.sqrt()) / qa;
    (t > 0.0 && oz + t * d.z >= 0.0).then_some(t)
}

/// The depth image the camera sees of the membrane `params` (0 where a ray misses it), for a camera of
/// `intrinsics` rotated by `t_sensor_camera` (its translation is replaced by the params' camera position).
pub fn render(
    params: &MembraneParams,
    intrinsics: &Intrinsics,
    t_sensor_camera: &DAffine3,
) -> Image {
    let v = params.to_vec();
    let rot = t_sensor_camera.matrix3;
    let mut out = Image::filled(intrinsics.width, intrinsics.height, 0.0);
    for row in 0..intrinsics.height {
        for col in 0..intrinsics.width {
            let d = rot * intrinsics.ray_dir(col as f64, row as f64);
            if let Some(t) = depth_along(&v, d) {
                *out.get_mut(col, row) = t as f32;
            }
        }
    }
    out
}

/// One measured pixel: its sensor-frame ray and depth.
struct Ray {
    d: DVec3,
    t: f64,
}

/// Solve the symmetric positive (semi-)definite system `m x = r` by Gaussian elimination with partial pivoting;
/// `None` when singular.
fn solve<const N: usize>(mut m: [[f64; N]; N], mut r: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if m[pivot][col].abs() < 1e-300 {
            return None;
        }
        m.swap(col, pivot);
        r.swap(col, pivot);
        let pivot_row = m[col];
        for row in col + 1..N {
            let f = m[row][col] / pivot_row[col];
            for (x, p) in m[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            r[row] -= f * r[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let s: f64 = (row + 1..N).map(|k| m[row][k] * x[k]).sum();
        x[row] = (r[row] - s) / m[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The algebraic fit (module docs): all six parameters from the rays, no starting point.
fn algebraic(rays: &[Ray]) -> Result<[f64; 6], MembraneFitError> {
    let row = |r: &Ray| {
        let (d, t) = (r.d, r.t);
        [
            t * t * d.x * d.x,
            t * t * d.y * d.y,
            2.0 * t * d.x,
            2.0 * t * d.y,
            2.0 * t * d.z,
            1.0,
        ]
    };
    // Columns scaled to unit RMS for a well-conditioned normal matrix.
    let mut scale = [0.0f64; 6];
    for r in rays {
        for (s, x) in scale.iter_mut().zip(row(r)) {
            *s += x * x;
        }
    }
    for s in &mut scale {
        *s = if *s > 0.0 {
            (*s / rays.len() as f64).sqrt()
        } else {
            1.0
        };
    }
    let mut m = [[0.0f64; 6]; 6];
    let mut rhs = [0.0f64; 6];
    for r in rays {
        let x = row(r);
        let x: [f64; 6] = std::array::from_fn(|i| x[i] / scale[i]);
        let y = -(r.t * r.d.z).powi(2);
        for i in 0..6 {
            rhs[i] += x[i] * y;
            for j in 0..6 {
                m[i][j] += x[i] * x[j];
            }
        }
    }
    let z = solve(m, rhs).ok_or(MembraneFitError::NotADome("undetermined"))?;
    let [aa, bb, pa, pb, oz, k] = std::array::from_fn(|i| z[i] / scale[i]);
    if !(aa > 0.0 && bb > 0.0) {
        return Err(MembraneFitError::NotADome("not an ellipsoid"));
    }
    let (ox, oy) = (pa / aa, pb / bb);
    let h2 = aa * ox * ox + bb * oy * oy + oz * oz - k;
    if h2.is_nan() || h2 <= 0.0 {
        return Err(MembraneFitError::NotADome("of negative height"));
    }
    let h = h2.sqrt();
    Ok([h / aa.sqrt(), h / bb.sqrt(), h, ox, oy, oz])
}

/// Median of `x` (sorted in place); 0 for an empty slice.
fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    x.sort_by(f64::total_cmp);
    let m = x.len() / 2;
    if x.len() % 2 == 1 {
        x[m]
    } else {
        0.5 * (x[m - 1] + x[m])
    }
}

/// Fit the membrane and camera position to `reference` (z-depth in metres, 0 where not measured), seen by a camera
/// of `intrinsics` rotated by `t_sensor_camera`'s rotation. `start` gives the values of parameters the config holds
/// fixed (and is otherwise only a fallback).
pub fn fit(
    reference: &Image,
    intrinsics: &Intrinsics,
    t_sensor_camera: &DAffine3,
    start: &MembraneParams,
    config: &MembraneFitConfig,
) -> Result<MembraneFit, MembraneFitError> {
    if (reference.width, reference.height) != (intrinsics.width, intrinsics.height) {
        return Err(MembraneFitError::Size {
            got_w: reference.width,
            got_h: reference.height,
            want_w: intrinsics.width,
            want_h: intrinsics.height,
        });
    }
    let rays = measured_rays(reference, intrinsics, t_sensor_camera);
    if rays.len() < 50 {
        return Err(MembraneFitError::TooFewPixels(rays.len()));
    }
    let fixed = start.to_vec();
    let free = free_parameters(config);
    // The algebraic start; parameters held fixed keep their values.
    let v = match algebraic(&rays) {
        Ok(a) => std::array::from_fn(|i| if free.contains(&i) { a[i] } else { fixed[i] }),
        Err(_) => fixed,
    };
    let refined = refine(&rays, &free, v, config);
    let res = &refined.res;
    let used: Vec<f64> = res.iter().flatten().copied().collect();
    if used.len() < 50 {
        return Err(MembraneFitError::NotADome("missed by most rays"));
    }
    let rms = (used.iter().map(|r| r * r).sum::<f64>() / used.len() as f64).sqrt();
    let max = used.iter().map(|r| r.abs()).fold(0.0, f64::max);
    // Standard errors: sigma^2 (J^T J)^-1 with sigma the residual's robust spread.
    let std = standard_errors(&refined.normal, &free, robust_sigma(res));
    Ok(MembraneFit {
        params: MembraneParams::from_vec(&refined.v),
        std_error: MembraneParams::from_vec(&std),
        residual_rms_m: rms,
        residual_max_m: max,
        pixels: used.len(),
        iterations: refined.iterations,
    })
}

/// The rays of the pixels of `reference` that hold a depth, in the sensor frame (rotated by `t_sensor_camera`).
fn measured_rays(
    reference: &Image,
    intrinsics: &Intrinsics,
    t_sensor_camera: &DAffine3,
) -> Vec<Ray> {
    let rot = t_sensor_camera.matrix3;
    let mut rays = Vec::with_capacity(reference.data.len());
    for row in 0..reference.height {
        for col in 0..reference.width {
            let t = f64::from(reference.get(col, row));
            if t.is_finite() && t > 0.0 {
                rays.push(Ray {
                    d: rot * intrinsics.ray_dir(col as f64, row as f64),
                    t,
                });
            }
        }
    }
    rays
}

/// The indices (into [`MembraneParams::to_vec`]'s layout) of the parameters `config` lets the fit change: the
/// inflation always, the footprint and the camera position where asked.
fn free_parameters(config: &MembraneFitConfig) -> Vec<usize> {
    (0..6)
        .filter(|&i| match i {
            0 | 1 => config.footprint,
            2 => true,
            _ => config.camera_position,
        })
        .collect()
}

/// Measured minus predicted depth along each ray for the parameters `v` (`None` where the ray misses the membrane).
fn residuals(rays: &[Ray], v: &[f64; 6]) -> Vec<Option<f64>> {
    rays.iter()
        .map(|r| depth_along(v, r.d).map(|t| r.t - t))
        .collect()
}

/// The residuals' robust spread: 1.4826 times their median absolute value (at least 1e-7 m).
fn robust_sigma(res: &[Option<f64>]) -> f64 {
    let mut abs: Vec<f64> = res.iter().flatten().map(|r| r.abs()).collect();
    (1.4826 * median(&mut abs)).max(1e-7)
}

/// The Huber cost of the residuals with threshold `k`, and how many rays it counts (those meeting the membrane).
fn huber_cost(res: &[Option<f64>], k: f64) -> (f64, usize) {
    let mut c = 0.0;
    let mut n = 0;
    for r in res.iter().flatten() {
        let a = r.abs();
        c += if a <= k {
            0.5 * a * a
        } else {
            k * (a - 0.5 * k)
        };
        n += 1;
    }
    (c, n)
}

/// Where the robust refinement ended.
struct Refined {
    /// The parameters ([`MembraneParams::to_vec`]'s layout).
    v: [f64; 6],
    /// Their residuals ([`residuals`]).
    res: Vec<Option<f64>>,
    /// The Huber-weighted normal matrix J^T W J of the free parameters, from the last iteration.
    normal: Vec<Vec<f64>>,
    /// Iterations run.
    iterations: usize,
}

/// The geometric refinement from `v`: Gauss-Newton on the depth residuals with Huber weights, damped
/// (Levenberg-Marquardt) until the Huber cost falls, over the `free` parameters; stops when a step no longer moves
/// them or after `config.iterations`.
fn refine(rays: &[Ray], free: &[usize], mut v: [f64; 6], config: &MembraneFitConfig) -> Refined {
    let mut res = residuals(rays, &v);
    let mut iterations = 0;
    let mut lambda = 1e-3;
    let n = free.len();
    let mut normal = vec![vec![0.0f64; n]; n];
    for _ in 0..config.iterations {
        iterations += 1;
        let k = config.huber_k * robust_sigma(&res);
        let (c0, n0) = huber_cost(&res, k);
        let g = weighted_normal_equations(rays, free, &v, &res, k, &mut normal);
        // Levenberg-Marquardt: damp until the Huber cost falls.
        let mut improved = false;
        for _ in 0..10 {
            let Some(step) = damped_step(&normal, &g, lambda) else {
                break;
            };
            let mut trial = v;
            for (j, &p) in free.iter().enumerate() {
                trial[p] += step[j];
            }
            let valid = trial[..3].iter().all(|&x| x > 0.0);
            let trial_res = residuals(rays, &trial);
            let (c1, n1) = huber_cost(&trial_res, k);
            if valid && n1 + n1 / 100 >= n0 && c1 <= c0 {
                let moved = free
                    .iter()
                    .enumerate()
                    .map(|(j, _)| step[j].abs())
                    .fold(0.0, f64::max);
                v = trial;
                res = trial_res;
                lambda = (lambda * 0.3).max(1e-9);
                improved = moved > 1e-9;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    Refined {
        v,
        res,
        normal,
        iterations,
    }
}

/// The Huber-weighted (threshold `k`) normal equations at `v` over the `free` parameters: `normal` is overwritten
/// with J^T W J, and J^T W r is returned, J the predicted depth's Jacobian by central differences.
fn weighted_normal_equations(
    rays: &[Ray],
    free: &[usize],
    v: &[f64; 6],
    res: &[Option<f64>],
    k: f64,
    normal: &mut [Vec<f64>],
) -> Vec<f64> {
    let n = free.len();
    // Jacobian of the predicted depth by central differences (the residual is measured - predicted).
    let mut jac = vec![vec![0.0f64; n]; rays.len()];
    for (j, &p) in free.iter().enumerate() {
        let step = 1e-6 * v[p].abs().max(1e-2);
        let (mut hi, mut lo) = (*v, *v);
        hi[p] += step;
        lo[p] -= step;
        for (i, r) in rays.iter().enumerate() {
            if let (Some(a), Some(b)) = (depth_along(&hi, r.d), depth_along(&lo, r.d)) {
                jac[i][j] = (a - b) / (2.0 * step);
            }
        }
    }
    let mut g = vec![0.0f64; n];
    for row in normal.iter_mut() {
        row.fill(0.0);
    }
    for (i, r) in res.iter().enumerate() {
        let Some(r) = *r else { continue };
        let w = if r.abs() <= k { 1.0 } else { k / r.abs() };
        for a in 0..n {
            g[a] += w * jac[i][a] * r;
            for b in 0..n {
                normal[a][b] += w * jac[i][a] * jac[i][b];
            }
        }
    }
    g
}

/// The Levenberg-Marquardt step of the free parameters (the first `g.len()` entries): `normal` with its diagonal
/// raised by `lambda` times itself, solved for `g`; `None` when singular.
fn damped_step(normal: &[Vec<f64>], g: &[f64], lambda: f64) -> Option<[f64; 6]> {
    let n = g.len();
    let mut m = [[0.0f64; 6]; 6];
    let mut rhs = [0.0f64; 6];
    for (a, row) in m.iter_mut().enumerate() {
        row[a] = 1.0;
    }
    for a in 0..n {
        rhs[a] = g[a];
        for b in 0..n {
            m[a][b] = normal[a][b];
        }
        m[a][a] += lambda * normal[a][a].max(1e-30);
    }
    solve(m, rhs)
}

/// Each free parameter's standard error, sigma times the square root of its diagonal entry of `normal`'s inverse
/// (0 for parameters held fixed, or where `normal` is singular).
fn standard_errors(normal: &[Vec<f64>], free: &[usize], sigma: f64) -> [f64; 6] {
    let n = free.len();
    let mut std = [0.0f64; 6];
    for (j, &p) in free.iter().enumerate() {
        let mut m = [[0.0f64; 6]; 6];
        let mut e = [0.0f64; 6];
        for (a, row) in m.iter_mut().enumerate() {
            row[a] = 1.0;
        }
        for a in 0..n {
            for b in 0..n {
                m[a][b] = normal[a][b];
            }
        }
        e[j] = 1.0;
        if let Some(col) = solve(m, e) {
            std[p] = sigma * col[j].max(0.0).sqrt();
        }
    }
    std
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::sensor::CameraConfig;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn nominal() -> MembraneParams {
        MembraneParams {
            footprint_m: [0.12, 0.08],
            inflation_m: 0.030,
            camera_position_m: [0.0, 0.0, -0.06],
        }
    }

    #[test]
    fn the_apex_ray_meets_the_dome_at_camera_distance_plus_inflation() {
        // Analytic: the optical axis from (0, 0, -c) meets the apex (0, 0, h) at depth c + h.
        let v = nominal().to_vec();
        let t = depth_along(&v, DVec3::new(0.0, 0.0, 1.0)).unwrap();
        assert!((t - 0.09).abs() < 1e-12, "{t}");
        // A ray along x from (0,0,-c): (t/2, 0, t - c) on x^2/a^2 + z^2/h^2 = 1.
        let t = depth_along(&v, DVec3::new(0.5, 0.0, 1.0)).unwrap();
        let (x, z) = (0.5 * t, t - 0.06);
        assert!((x * x / 0.0036 + z * z / 0.0009 - 1.0).abs() < 1e-9);
        // Pointing sideways below the base: it leaves the ellipsoid below z = 0.
        assert!(depth_along(&v, DVec3::new(1.0, 0.0, 0.01)).is_none());
    }

    #[test]
    fn an_off_nominal_membrane_is_recovered_from_a_noisy_reference() {
        let k = CameraConfig::default().native;
        let truth = MembraneParams {
            footprint_m: [0.126, 0.077],
            inflation_m: 0.0325,
            camera_position_m: [0.0015, -0.001, -0.0575],
        };
        let mut img = render(&truth, &k, &DAffine3::IDENTITY);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise = Normal::new(0.0, 0.0005).unwrap();
        for d in &mut img.data {
            *d += noise.sample(&mut rng) as f32;
        }
        // Everything free: the depth image is matched to its noise, though a wider footprint and a camera further
        // back look almost alike (the standard errors say so).
        let all = MembraneFitConfig {
            footprint: true,
            ..MembraneFitConfig::default()
        };
        let f = fit(&img, &k, &DAffine3::IDENTITY, &nominal(), &all).unwrap();
        let (p, sd) = (f.params, f.std_error);
        assert!(
            (p.inflation_m - 0.0325).abs() < 4.0 * sd.inflation_m,
            "{f:?}"
        );
        assert!(
            (p.footprint_m[0] - 0.126).abs() < 4.0 * sd.footprint_m[0],
            "{f:?}"
        );
        assert!(
            (p.footprint_m[1] - 0.077).abs() < 4.0 * sd.footprint_m[1],
            "{f:?}"
        );
        assert!((f.residual_rms_m - 0.0005).abs() < 5e-5, "{f:?}");
        // With the footprint known (the default holds it), inflation and camera position come out sharp.
        let known = MembraneParams {
            footprint_m: truth.footprint_m,
            ..nominal()
        };
        let f = fit(
            &img,
            &k,
            &DAffine3::IDENTITY,
            &known,
            &MembraneFitConfig::default(),
        )
        .unwrap();
        let p = f.params;
        assert!((p.inflation_m - 0.0325).abs() < 5e-5, "{f:?}");
        for i in 0..3 {
            let err = (p.camera_position_m[i] - truth.camera_position_m[i]).abs();
            assert!(err < 5e-5, "{f:?}");
        }
        assert_eq!(p.footprint_m, truth.footprint_m);
        // The residual is the noise that was added.
        assert!((f.residual_rms_m - 0.0005).abs() < 5e-5, "{f:?}");
        assert!(
            f.std_error.inflation_m > 0.0 && f.std_error.inflation_m < 1e-4,
            "{f:?}"
        );
    }

    #[test]
    fn fixed_parameters_keep_their_values_and_outliers_do_not_move_the_fit() {
        let k = CameraConfig::default().native;
        let truth = MembraneParams {
            inflation_m: 0.028,
            ..nominal()
        };
        let mut img = render(&truth, &k, &DAffine3::IDENTITY);
        // A dent: 300 pixels pushed 8 mm towards the camera (a contact that slipped into the reference).
        for d in img.data.iter_mut().take(300) {
            *d -= 0.008;
        }
        let config = MembraneFitConfig {
            footprint: false,
            camera_position: false,
            ..Default::default()
        };
        let f = fit(&img, &k, &DAffine3::IDENTITY, &nominal(), &config).unwrap();
        assert_eq!(f.params.footprint_m, [0.12, 0.08]);
        assert_eq!(f.params.camera_position_m, [0.0, 0.0, -0.06]);
        assert!(
            (f.params.inflation_m - 0.028).abs() < 2e-5,
            "{:?}",
            f.params
        );
        assert_eq!(f.std_error.camera_position_m, [0.0; 3]);
    }

    #[test]
    fn a_flat_or_tiny_reference_is_refused() {
        let k = CameraConfig::default().native;
        let e = fit(
            &Image::filled(10, 10, 0.09),
            &k,
            &DAffine3::IDENTITY,
            &nominal(),
            &MembraneFitConfig::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("10x10"), "{e}");
        let mut empty = Image::filled(k.width, k.height, 0.0);
        empty.data[..10].fill(0.09);
        assert!(matches!(
            fit(
                &empty,
                &k,
                &DAffine3::IDENTITY,
                &nominal(),
                &MembraneFitConfig::default()
            ),
            Err(MembraneFitError::TooFewPixels(10))
        ));
    }
}
