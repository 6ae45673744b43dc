//! `tnd bench pose`: time a K-initialisation SE(2) registration and report its errors, on a simulated Soft Bubble
//! contact or on the peer's saved problem (`../shared/peers/chsel_register.py --out-dir DIR`, lengths in mm) so that
//! both solve the same one. Optional perturbations (noise, outliers, a partial patch) probe robustness.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde_json::json;
use tactile_derender::io::npy;
use tactile_derender::mesh::{self, LoadOptions, Mesh, Units};
use tactile_derender::objects::{ObjectSet, RotationSymmetry};
use tactile_derender::pose::{
    initial_poses, register, InitStrategy, ObjectSdf, RegistrationProblem, SdfRegistration,
    SdfRegistrationConfig,
};
use tactile_derender::recon::{back_project, free_space_points, FreeSpaceConfig};
use tactile_derender::sensor::{Scene, Se2};
use tactile_derender::sim::{PreparedObject, SimConfig, Simulator};

use super::median_time;

#[derive(Args, Debug)]
pub struct PoseBenchArgs {
    /// Print JSON lines (the only output format).
    #[arg(long)]
    pub json: bool,
    /// The peer's saved problem directory (surface_points_mm.npy, free_points_mm.npy, inits_obj_to_world_mm.npy,
    /// problem.json, cylinder_mm.obj).
    #[arg(long)]
    pub problem: Option<PathBuf>,
    /// Object for the simulated problem (built-in name).
    #[arg(long, default_value = "cross_w12_s50")]
    pub object: String,
    /// True pose X,Y,THETA of the simulated problem (metres, radians).
    #[arg(long, default_value = "0.004,-0.003,0.5")]
    pub pose: String,
    /// Press depth of the simulated problem, metres.
    #[arg(long, default_value_t = 0.006)]
    pub press: f64,
    /// Number of random starts (ignored with --problem, which brings its own).
    #[arg(long, value_parser = crate::args::at_most::<10_000>, default_value_t = 10)]
    pub inits: usize,
    /// Timed repetitions (median reported).
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Threads for the registration (rayon).
    #[arg(long, value_parser = crate::args::at_most::<1024>, default_value_t = 2)]
    pub threads: usize,
    /// Gaussian noise added to every surface point, mm (isotropic 3-D).
    #[arg(long, default_value_t = 0.0)]
    pub noise_mm: f64,
    /// Fraction of surface points replaced by outliers (uniform within 10 mm of the points' bounding box).
    #[arg(long, default_value_t = 0.0)]
    pub outliers: f64,
    /// Keep only this fraction of the surface points (those with the smallest coordinate along the world x axis):
    /// a partial patch.
    #[arg(long, default_value_t = 1.0)]
    pub keep: f64,
    /// Drop the free-space points (surface term only).
    #[arg(long)]
    pub no_free: bool,
    /// Seed of the perturbations and random starts.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// With --problem: save the perturbed problem in the peer's format here (for running the peer's ICP on it with
    /// tests/fixtures/pose_icp_on_problem.py).
    #[arg(long)]
    pub write_problem: Option<PathBuf>,
}

/// One registration problem in metres.
struct Problem {
    mesh: Mesh,
    surface: Vec<DVec3>,
    free: Vec<DVec3>,
    inits: Option<Vec<Se2>>,
    truth: Se2,
    /// Rotational symmetry for the yaw error (the peer's cylinder: 2-fold).
    rotation: RotationSymmetry,
    source: String,
}

fn read_points_mm(path: &Path) -> Result<Vec<DVec3>> {
    let a = npy::read(path)?;
    match a.shape.as_slice() {
        [_, 3] => {}
        [0] => return Ok(Vec::new()),
        s => bail!(
            "{}: expected an (N, 3) array of points in mm, found shape {s:?}",
            path.display()
        ),
    }
    let pts: Vec<DVec3> = a
        .data
        .chunks_exact(3)
        .map(|c| DVec3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2])) * 1e-3)
        .collect();
    if let Some(i) = pts.iter().position(|p| !p.is_finite()) {
        bail!("{}: point {i} is not finite", path.display());
    }
    Ok(pts)
}

/// SE(2) of a 4x4 object->world matrix in mm (row-major 16 values).
fn se2_of_matrix_mm(m: &[f64]) -> Se2 {
    Se2::new(m[3] * 1e-3, m[7] * 1e-3, m[4].atan2(m[0]))
}

fn load_peer_problem(dir: &Path) -> Result<Problem> {
    let surface = read_points_mm(&dir.join("surface_points_mm.npy"))?;
    let free_path = dir.join("free_points_mm.npy");
    let free = if free_path.exists() {
        read_points_mm(&free_path)?
    } else {
        Vec::new()
    };
    let inits_path = dir.join("inits_obj_to_world_mm.npy");
    let a = npy::read(&inits_path)?;
    if a.shape.len() != 3 || a.shape[1..] != [4, 4] {
        bail!(
            "{}: expected (K, 4, 4) matrices, found shape {:?}",
            inits_path.display(),
            a.shape
        );
    }
    let inits = a
        .data
        .chunks_exact(16)
        .map(|c| se2_of_matrix_mm(&c.iter().map(|&x| f64::from(x)).collect::<Vec<_>>()))
        .collect();
    let json_path = dir.join("problem.json");
    let text = std::fs::read_to_string(&json_path)
        .with_context(|| format!("{}: cannot read", json_path.display()))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: malformed JSON", json_path.display()))?;
    let gt: Vec<f64> = v["gt_obj_to_world_mm"]
        .as_array()
        .ok_or_else(|| anyhow!("{}: no gt_obj_to_world_mm", json_path.display()))?
        .iter()
        .flat_map(|row| row.as_array().cloned().unwrap_or_default())
        .filter_map(|x| x.as_f64())
        .collect();
    if gt.len() != 16 {
        bail!(
            "{}: gt_obj_to_world_mm must be a 4x4 matrix",
            json_path.display()
        );
    }
    let options = LoadOptions {
        units: Units::Mm,
        fit_to_size: None,
    };
    let mesh = mesh::load(&dir.join("cylinder_mm.obj"), &options)?;
    Ok(Problem {
        mesh,
        surface,
        free,
        inits: Some(inits),
        truth: se2_of_matrix_mm(&gt),
        rotation: RotationSymmetry::NFold(2),
        source: dir.display().to_string(),
    })
}

fn simulated_problem(a: &PoseBenchArgs) -> Result<Problem> {
    let set = ObjectSet::builtin();
    let mesh = set.mesh(&a.object)?;
    let rotation = set
        .find(&a.object)
        .map(|e| e.symmetry.rotation)
        .unwrap_or_default();
    let truth = Se2::parse(&a.pose).map_err(|e| anyhow!(e))?;
    let mut cfg = SimConfig::default();
    cfg.signature.noise_std = 0.0;
    let sim = Simulator::new(cfg)?;
    let object = PreparedObject::new(mesh.clone())?;
    let sensor = sim.pressing_pose(&object, 0.0, 0.0, 0.0, a.press);
    let out = sim.simulate(
        &object,
        &Scene {
            object: truth,
            sensor,
        },
        a.seed,
    );
    let t_world_camera = sim.t_world_camera(&sensor);
    let surface = back_project(&out.target, sim.intrinsics(), &t_world_camera).p_world;
    let free = free_space_points(
        &out.target,
        sim.nominal_depth(),
        sim.intrinsics(),
        &t_world_camera,
        &FreeSpaceConfig::default(),
        a.seed,
    );
    Ok(Problem {
        mesh,
        surface,
        free,
        inits: None,
        truth,
        rotation,
        source: format!("simulated {} at {}", a.object, a.pose),
    })
}

/// Noise, outliers and cropping, as asked.
fn perturb(p: &mut Problem, a: &PoseBenchArgs) -> Result<()> {
    let mut rng = ChaCha8Rng::seed_from_u64(a.seed ^ 0x5eed);
    if !(0.0..=1.0).contains(&a.keep) || !(0.0..1.0).contains(&a.outliers) || a.noise_mm < 0.0 {
        bail!("--keep must be in (0, 1], --outliers in [0, 1) and --noise-mm >= 0");
    }
    if a.keep < 1.0 {
        p.surface.sort_by(|u, v| u.x.total_cmp(&v.x));
        let n = ((p.surface.len() as f64 * a.keep).round() as usize).max(3);
        p.surface.truncate(n);
    }
    if a.noise_mm > 0.0 {
        let normal = Normal::new(0.0, a.noise_mm * 1e-3)?;
        for q in &mut p.surface {
            *q += DVec3::new(
                normal.sample(&mut rng),
                normal.sample(&mut rng),
                normal.sample(&mut rng),
            );
        }
    }
    if a.outliers > 0.0 {
        let lo = p.surface.iter().copied().fold(DVec3::INFINITY, DVec3::min) - DVec3::splat(0.01);
        let hi = p
            .surface
            .iter()
            .copied()
            .fold(DVec3::NEG_INFINITY, DVec3::max)
            + DVec3::splat(0.01);
        for q in &mut p.surface {
            if rng.random::<f64>() < a.outliers {
                *q = DVec3::new(
                    rng.random_range(lo.x..hi.x),
                    rng.random_range(lo.y..hi.y),
                    rng.random_range(lo.z..hi.z),
                );
            }
        }
    }
    if a.no_free {
        p.free.clear();
    }
    Ok(())
}

fn yaw_error_deg(est: Se2, truth: Se2, rotation: RotationSymmetry) -> Option<f64> {
    tactile_derender::metrics::pose::theta_error_rad(est, truth, rotation).map(f64::to_degrees)
}

pub fn run(a: &PoseBenchArgs) -> Result<()> {
    crate::args::check_press("--press", a.press, false)?;
    let mut p = match &a.problem {
        Some(dir) => load_peer_problem(dir)?,
        None => simulated_problem(a)?,
    };
    perturb(&mut p, a)?;
    if let (Some(out), Some(src)) = (&a.write_problem, &a.problem) {
        let _out = crate::outputs::folder("--write-problem", out, false, &[src])?;
        write_problem(out, src, &p)?;
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.max(1))
        .build()?;
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "{}",
        json!({"bench": "info", "tool": "tnd", "host": super::host(), "problem": p.source, "threads": a.threads,
               "loadavg": load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")})
    );
    let config = SdfRegistrationConfig {
        parallel: a.threads > 1,
        ..Default::default()
    };
    let t0 = Instant::now();
    let reg = pool.install(|| SdfRegistration::new(&p.mesh, config))?;
    let setup_s = t0.elapsed().as_secs_f64();
    let grid_accuracy = grid_accuracy(&reg, &p);
    let [nx, ny, nz] = reg.grid().dims();
    println!(
        "{}",
        json!({"bench": "register_setup", "setup_s": setup_s, "grid_nodes": [nx, ny, nz],
               "grid_spacing_mm": reg.config().grid.spacing_m * 1e3,
               "grid_err_at_surface_max_mm": grid_accuracy.0, "grid_err_at_surface_mean_mm": grid_accuracy.1,
               "grid_err_band5mm_max_mm": grid_accuracy.2, "grid_err_band5mm_mean_mm": grid_accuracy.3})
    );
    let problem = RegistrationProblem {
        surface: &p.surface,
        free: &p.free,
    };
    let strategy = InitStrategy::Random {
        count: a.inits,
        radius_m: 0.01,
        seed: a.seed,
    };
    let inits = match &p.inits {
        Some(i) => i.clone(),
        None => initial_poses(&strategy, &problem)?,
    };
    // Register through the fixed-start driver, once per start, inside the pool (the same work as `register` with
    // the K starts, which `refine` parallelises).
    let solve = || -> Result<Vec<tactile_derender::pose::Hypothesis>> {
        use tactile_derender::pose::Registration;
        problem.validate()?;
        let mut h = reg.refine(&problem, &inits)?;
        h.sort_by(|x, y| x.cost.total_cmp(&y.cost));
        Ok(h)
    };
    let mut result = Ok(Vec::new());
    let wall_s = pool.install(|| median_time(1, a.runs, || result = solve()));
    let hyps = result?;
    // Sanity: the public driver gives the same best pose.
    let check = pool.install(|| register(&reg, &problem, &InitStrategy::Fixed(hyps[0].pose)))?;
    let best = hyps[0];
    let trans = |s: Se2| ((s.x - p.truth.x).powi(2) + (s.y - p.truth.y).powi(2)).sqrt() * 1e3;
    let yaws: Vec<Option<f64>> = hyps
        .iter()
        .map(|h| yaw_error_deg(h.pose, p.truth, p.rotation))
        .collect();
    let mut trans_all: Vec<f64> = hyps.iter().map(|h| trans(h.pose)).collect();
    trans_all.sort_by(f64::total_cmp);
    println!(
        "{}",
        json!({"bench": "register", "method": "tnd sdf-lm (CHSEL-inspired, grid + exact polish)",
               "inits": inits.len(), "wall_s": wall_s, "runs": a.runs, "threads": a.threads,
               "surface_points": p.surface.len(), "free_points": p.free.len(),
               "noise_mm": a.noise_mm, "outliers": a.outliers, "keep": a.keep,
               "trans_err_xy_mm": trans(best.pose), "yaw_err_deg": yaws[0],
               "cost_best": best.cost, "iterations_best": best.iterations,
               "trans_err_xy_mm_min": trans_all[0], "trans_err_xy_mm_median": trans_all[trans_all.len() / 2],
               "refit_from_best_moves_mm": trans(check[0].pose) - trans(best.pose),
               "estimate": best.pose, "truth": p.truth})
    );
    Ok(())
}

/// |grid − exact| at the surface points under the true pose, and at random points within 5 mm of them (mm):
/// (max, mean) each.
fn grid_accuracy(reg: &SdfRegistration, p: &Problem) -> (f64, f64, f64, f64) {
    let t = p.truth.to_affine().inverse();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let (mut s_max, mut s_sum, mut b_max, mut b_sum) = (0.0f64, 0.0, 0.0f64, 0.0);
    let n = p.surface.len().max(1) as f64;
    for q in &p.surface {
        let q_obj = t.transform_point3(*q);
        let e = (reg.grid().value(q_obj) - reg.exact_sdf().value(q_obj)).abs() * 1e3;
        s_max = s_max.max(e);
        s_sum += e;
        let r = DVec3::new(
            rng.random_range(-0.005..0.005),
            rng.random_range(-0.005..0.005),
            rng.random_range(-0.005..0.005),
        );
        let e = (reg.grid().value(q_obj + r) - reg.exact_sdf().value(q_obj + r)).abs() * 1e3;
        b_max = b_max.max(e);
        b_sum += e;
    }
    (s_max, s_sum / n, b_max, b_sum / n)
}

/// Save the (perturbed) problem in the peer's format: points in mm (float32), the starts, and the source's mesh and
/// problem.json.
fn write_problem(out: &Path, src: &Path, p: &Problem) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let pts = |v: &[DVec3]| -> Vec<f32> {
        v.iter()
            .flat_map(|q| (*q * 1e3).to_array().map(|x| x as f32))
            .collect()
    };
    let save = |name: &str, bytes: Vec<u8>| {
        let path = out.join(name);
        tactile_derender::io::write_atomic(&path, &bytes)
            .with_context(|| format!("{}: cannot write", path.display()))
    };
    save(
        "surface_points_mm.npy",
        npy::encode_f32(&[p.surface.len(), 3], &pts(&p.surface)),
    )?;
    save(
        "free_points_mm.npy",
        npy::encode_f32(&[p.free.len(), 3], &pts(&p.free)),
    )?;
    for name in [
        "inits_obj_to_world_mm.npy",
        "problem.json",
        "cylinder_mm.obj",
    ] {
        std::fs::copy(src.join(name), out.join(name)).with_context(|| {
            format!(
                "{}: cannot copy into {}",
                src.join(name).display(),
                out.display()
            )
        })?;
    }
    Ok(())
}
