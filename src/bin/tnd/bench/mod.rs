//! `tnd bench`: benchmarks printing one JSON object per line, shaped like the peer scripts' records
//! (`../shared/peers/`) so that both can be merged and compared (run them back to back: these machines drift).

mod gemm;
mod pose;
mod posterior;
mod track;
mod unet;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, Context, Result};
use clap::{Args, Subcommand};
use glam::{DAffine3, DMat3, DVec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde_json::json;
use tactile_derender::image::Image;
use tactile_derender::io::npy;
use tactile_derender::mesh::{self, LoadOptions, Mesh, RayCaster, SignedDistance, Units};
use tactile_derender::objects::ObjectSet;
use tactile_derender::sensor::{Intrinsics, Scene, Se2};
use tactile_derender::sim::contact::{self, ElastomerSdf};
use tactile_derender::sim::{render, PreparedObject, SimConfig, Simulator};

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub command: BenchCommand,
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Ray casting (rays/s) and full synthetic pairs (pairs/s).
    Sim(SimBenchArgs),
    /// SE(2) registration from K starts: wall time and pose errors (optionally the peer's saved problem).
    Pose(pose::PoseBenchArgs),
    /// The N-sample pose posterior of `tnd pose`'s pipeline (sampling, press, registration, check), stage by stage.
    Posterior(Box<posterior::PosteriorBenchArgs>),
    /// `tnd recording track` on one recording: seconds per contact frame and errors, carried against per-frame.
    Track(Box<track::TrackBenchArgs>),
    /// U-Net forward and training step against `../shared/peers/unet_torch.py`.
    Unet(unet::UnetBenchArgs),
    /// The tiled convolution's three GEMM patterns, our AVX-512 kernels against the `gemm` crate (GFLOP/s).
    Gemm(gemm::GemmBenchArgs),
}

#[derive(Args, Debug)]
pub struct SimBenchArgs {
    /// Print JSON lines (the only output format; accepted for symmetry with the other benches).
    #[arg(long)]
    pub json: bool,
    /// The peer's saved problem (`raycast_open3d.py --out-dir`): time its meshes and cameras and compare depths.
    #[arg(long)]
    pub peer_dir: Option<PathBuf>,
    /// Timed runs per 64x64 measurement (larger images use a quarter).
    #[arg(long, default_value_t = 200)]
    pub runs: usize,
    /// Synthetic pairs to time.
    #[arg(long, value_parser = crate::args::at_most::<10_000_000>, default_value_t = 2000)]
    pub pairs: usize,
    /// Thread counts to time the ray casts with.
    #[arg(long, value_parser = crate::args::at_most::<1024>, value_delimiter = ',', default_value = "1,2")]
    pub threads: Vec<usize>,
}

pub fn run(a: BenchArgs) -> Result<()> {
    match a.command {
        BenchCommand::Sim(s) => bench_sim(&s),
        BenchCommand::Pose(p) => pose::run(&p),
        BenchCommand::Posterior(p) => posterior::run(&p),
        BenchCommand::Track(t) => track::run(&t),
        BenchCommand::Unet(u) => unet::run(&u),
        BenchCommand::Gemm(g) => gemm::run(&g),
    }
}

/// Median of `runs` timed calls after `warmup` untimed ones, in seconds.
pub fn median_time(warmup: usize, runs: usize, mut f: impl FnMut()) -> f64 {
    for _ in 0..warmup {
        f();
    }
    let mut t: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

fn emit(v: serde_json::Value) {
    println!("{v}");
}

/// The peer's scene: a camera 80 mm from the origin on -y looking at it (up +z), vertical FOV 60°, square image.
fn peer_camera(size: usize) -> (Intrinsics, DAffine3) {
    let f = (size as f64 / 2.0) / 30f64.to_radians().tan();
    // The peer puts pixel centres at u + 0.5 with cx = W/2; ours are at integer u.
    let k = Intrinsics {
        width: size,
        height: size,
        fx: f,
        fy: f,
        cx: size as f64 / 2.0 - 0.5,
        cy: size as f64 / 2.0 - 0.5,
    };
    let rot = DMat3::from_cols(DVec3::X, DVec3::new(0.0, 0.0, -1.0), DVec3::Y);
    (
        k,
        DAffine3::from_mat3_translation(rot, DVec3::new(0.0, -0.080, 0.0)),
    )
}

fn bench_meshes(peer_dir: Option<&Path>) -> Result<Vec<(String, Mesh)>> {
    match peer_dir {
        Some(dir) => ["cylinder", "icosphere"]
            .iter()
            .map(|name| {
                let options = LoadOptions {
                    units: Units::Mm,
                    fit_to_size: None,
                };
                Ok((
                    name.to_string(),
                    mesh::load(&dir.join(format!("{name}.obj")), &options)?,
                ))
            })
            .collect(),
        None => Ok(vec![
            ("cylinder".into(), peer_cylinder(0.015, 0.060, 100, 9)?),
            ("icosphere".into(), peer_icosphere(0.020, 5)?),
        ]),
    }
}

/// The processor the figures were taken on (`/proc/cpuinfo`'s model name and family, "unknown" elsewhere) and
/// its core count: ratios against a peer differ between CPUs, so every benchmark's info record carries it.
pub(crate) fn host() -> serde_json::Value {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let field = |name: &str| {
        info.lines()
            .find(|l| l.split(':').next().is_some_and(|k| k.trim() == name))
            .and_then(|l| l.split_once(':'))
            .map_or_else(|| "unknown".to_string(), |(_, v)| v.trim().to_string())
    };
    json!({"cpu": field("model name"), "cpu_family": field("cpu family"),
           "cpus": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)})
}

fn bench_sim(a: &SimBenchArgs) -> Result<()> {
    emit(
        json!({"bench": "info", "tool": "tnd", "version": env!("CARGO_PKG_VERSION"), "host": host(),
        "cpus": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        "peer_dir": a.peer_dir}),
    );
    for (name, mesh) in bench_meshes(a.peer_dir.as_deref())? {
        let t0 = Instant::now();
        let caster = RayCaster::new(&mesh)?;
        let build_s = t0.elapsed().as_secs_f64();
        emit(
            json!({"bench": "raycast_build", "backend": "tnd BVH4 (binned SAH)", "mesh": name,
            "triangles": mesh.triangles().len(), "median_s": build_s}),
        );
        for size in [64usize, 256] {
            let (k, t_world_camera) = peer_camera(size);
            let runs = if size <= 64 {
                a.runs
            } else {
                (a.runs / 4).max(1)
            };
            for &threads in &a.threads {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()?;
                let mut depth = None;
                let median_s = pool.install(|| {
                    median_time(5, runs, || {
                        depth = Some(render::render_depth(&caster, &k, &t_world_camera))
                    })
                });
                let depth = depth.ok_or_else(|| anyhow!("no run"))?;
                let hits = depth.data.iter().filter(|&&d| d > 0.0).count();
                let depth_sum_mm: f64 = depth.data.iter().map(|&d| f64::from(d) * 1e3).sum();
                let mut rec = json!({"bench": "raycast", "backend": "tnd render_depth (BVH4)",
                    "mesh": name, "triangles": mesh.triangles().len(), "width": size, "height": size,
                    "rays": size * size, "nthreads": threads, "median_s": median_s, "runs": runs,
                    "rays_per_s": (size * size) as f64 / median_s, "hits": hits, "depth_sum": depth_sum_mm});
                if let Some(dir) = &a.peer_dir {
                    let path = dir.join(format!("depth_{name}_{size}x{size}.npy"));
                    let peer = npy::read(&path).with_context(|| format!("{}", path.display()))?;
                    let mut mismatch = 0;
                    let mut max_diff = 0.0f64;
                    for (&ours, &theirs) in depth.data.iter().zip(&peer.data) {
                        match (ours > 0.0, theirs.is_finite()) {
                            (true, true) => {
                                max_diff =
                                    max_diff.max((f64::from(ours) * 1e3 - f64::from(theirs)).abs())
                            }
                            (false, false) => {}
                            _ => mismatch += 1,
                        }
                    }
                    rec["hit_mismatch_vs_open3d"] = mismatch.into();
                    rec["max_abs_depth_diff_mm_vs_open3d"] = max_diff.into();
                }
                emit(rec);
            }
        }
    }
    bench_pairs(a.pairs)
}

/// Full synthetic pairs (render, contact, shadows, noise) at 64x64 over the built-in objects, parallel over pairs.
fn bench_pairs(pairs: usize) -> Result<()> {
    let sim = Simulator::new(SimConfig::default())?;
    let set = ObjectSet::builtin();
    let objects: Vec<PreparedObject> = set
        .entries()
        .iter()
        .map(|e| Ok(PreparedObject::new(set.mesh(&e.name)?)?))
        .collect::<Result<_>>()?;
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let jobs: Vec<(usize, Scene, u64)> = (0..pairs)
        .map(|i| {
            let o = rng.random_range(0..objects.len());
            let pose = Se2::new(
                rng.random_range(-0.015..0.015),
                rng.random_range(-0.015..0.015),
                rng.random_range(0.0..std::f64::consts::TAU),
            );
            let press = rng.random_range(0.003..0.015);
            let scene = Scene {
                object: pose,
                sensor: sim.pressing_pose(&objects[o], 0.0, 0.0, 0.0, press),
            };
            (o, scene, i as u64)
        })
        .collect();
    let t0 = Instant::now();
    let contact: usize = jobs
        .par_iter()
        .map(|(o, scene, seed)| sim.simulate(&objects[*o], scene, *seed).contact_pixels)
        .sum();
    let wall_s = t0.elapsed().as_secs_f64();
    let (w, h) = sim.config().camera.resolution;
    emit(
        json!({"bench": "pairs", "width": w, "height": h, "pairs": pairs, "wall_s": wall_s,
        "pairs_per_s": pairs as f64 / wall_s, "mean_contact_pixels": contact as f64 / pairs.max(1) as f64,
        "threads": rayon::current_num_threads()}),
    );
    // The contact step alone on the same depth images: the simulator's membrane test (certain answers from the
    // half-ellipsoid, the exact signed distance near its surface) against the exact signed distance everywhere.
    let depths: Vec<_> = jobs
        .par_iter()
        .map(|(o, scene, _)| sim.render_depth(&objects[*o], scene))
        .collect();
    let mesh = sim.elastomer_mesh();
    let exact = ElastomerSdf::new(SignedDistance::new(mesh)?, mesh.aabb());
    let t_sensor_camera = sim.t_sensor_camera();
    let time = |f: &(dyn Fn(&Image) -> Image + Sync)| {
        let mut masks = Vec::new();
        let s = median_time(0, 3, || {
            masks = depths.par_iter().map(f).collect::<Vec<_>>();
        });
        (s, masks)
    };
    let (fast_s, fast) = time(&|d| sim.contact(d).0);
    let (exact_s, slow) =
        time(&|d| contact::contact(d, sim.intrinsics(), &t_sensor_camera, &exact).0);
    let differing: usize = fast
        .iter()
        .zip(&slow)
        .map(|(a, b)| a.data.iter().zip(&b.data).filter(|(x, y)| x != y).count())
        .sum();
    emit(
        json!({"bench": "contact", "pairs": pairs, "membrane_test_s": fast_s, "exact_sdf_s": exact_s,
        "ratio": fast_s / exact_s, "differing_mask_pixels": differing}),
    );
    Ok(())
}

/// The peer's cylinder (Open3D `create_cylinder`): `2 * resolution` cap triangles plus `2 * resolution * split` side
/// triangles (100 and 9 give 2000), centred at the origin, axis z.
fn peer_cylinder(radius: f32, height: f32, resolution: u32, split: u32) -> Result<Mesh> {
    use glam::Vec3;
    let mut v = vec![
        Vec3::new(0.0, 0.0, height / 2.0),
        Vec3::new(0.0, 0.0, -height / 2.0),
    ];
    for s in 0..=split {
        let z = height / 2.0 - height * s as f32 / split as f32;
        for r in 0..resolution {
            let a = std::f32::consts::TAU * r as f32 / resolution as f32;
            v.push(Vec3::new(radius * a.cos(), radius * a.sin(), z));
        }
    }
    let ring = |s: u32, r: u32| 2 + s * resolution + r % resolution;
    let mut t = Vec::new();
    for r in 0..resolution {
        t.push([0, ring(0, r), ring(0, r + 1)]);
        t.push([1, ring(split, r + 1), ring(split, r)]);
        for s in 0..split {
            t.push([ring(s, r), ring(s + 1, r), ring(s + 1, r + 1)]);
            t.push([ring(s, r), ring(s + 1, r + 1), ring(s, r + 1)]);
        }
    }
    Ok(Mesh::from_raw(v, t, "bench cylinder")?)
}

/// An icosphere of `20 * 4^subdivisions` triangles (the peer's trimesh icosphere).
fn peer_icosphere(radius: f32, subdivisions: u32) -> Result<Mesh> {
    use glam::Vec3;
    use std::collections::HashMap;
    let p = (1.0 + 5f32.sqrt()) / 2.0;
    let mut v: Vec<Vec3> = [
        (-1.0, p, 0.0),
        (1.0, p, 0.0),
        (-1.0, -p, 0.0),
        (1.0, -p, 0.0),
        (0.0, -1.0, p),
        (0.0, 1.0, p),
        (0.0, -1.0, -p),
        (0.0, 1.0, -p),
        (p, 0.0, -1.0),
        (p, 0.0, 1.0),
        (-p, 0.0, -1.0),
        (-p, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut t: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, v: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push(((v[a as usize] + v[b as usize]) * 0.5).normalize());
                (v.len() - 1) as u32
            })
        };
        t = t
            .iter()
            .flat_map(|&[a, b, c]| {
                let ab = midpoint(a, b, &mut v);
                let bc = midpoint(b, c, &mut v);
                let ca = midpoint(c, a, &mut v);
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    let v = v.into_iter().map(|x| x * radius).collect();
    Ok(Mesh::from_raw(v, t, "bench icosphere")?)
}
