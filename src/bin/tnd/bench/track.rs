//! `tnd bench track`: the wall time per contact frame of `tnd recording track` on one recording, the tracker that
//! carries each frame's estimate forward (the default) against per-frame tracking (`--per-frame`, every frame from
//! scratch) run in the same process, frame by frame interleaved (these machines drift), with the errors of each
//! against the recorded poses. One JSON line per tracker, then one comparing them (medians and ratios).

use std::time::Instant;

use anyhow::Result;
use clap::Args;
use serde_json::{json, Value};
use tactile_derender::pipeline::track::{FrameTrack, Tracker, TrackingConfig};

use crate::progress;
use crate::track_cmd::{open, TrackInputArgs};

#[derive(Args, Debug)]
pub struct TrackBenchArgs {
    /// Print JSON lines (the only output format).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub input: TrackInputArgs,
    /// Track every n-th frame.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
}

/// Median of `v` (NaN when empty).
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// One tracker's record: seconds per frame and errors against the recorded poses.
fn record(name: &str, times: &[f64], rows: &[FrameTrack]) -> Value {
    let position: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.estimate_error.map(|e| e.0))
        .collect();
    let theta: Vec<f64> = rows
        .iter()
        .filter_map(|r| r.estimate_error.and_then(|e| e.1).map(f64::abs))
        .collect();
    json!({
        "bench": "track", "tracker": name, "frames": times.len(),
        "carried_frames": rows.iter().filter(|r| r.carried).count(),
        "median_s_per_frame": median(times.to_vec()), "mean_s_per_frame": mean(times),
        "scored_frames": position.len(),
        "mean_position_err_mm": mean(&position), "median_position_err_mm": median(position.clone()),
        "mean_theta_err_deg": mean(&theta), "median_theta_err_deg": median(theta),
        "no_estimate": rows.iter().filter(|r| r.estimate.is_none()).count(),
    })
}

pub fn run(a: &TrackBenchArgs) -> Result<()> {
    let sim_config = a.input.sensor.sim_config()?;
    let opened = open(&a.input, sim_config)?;
    let per_frame = TrackingConfig {
        per_frame: true,
        ..a.input.tracking.clone()
    };
    let mut carried = Tracker::new(opened.context(&a.input))?;
    let mut scratch = Tracker::new(tactile_derender::pipeline::track::TrackContext {
        tracking: &per_frame,
        ..opened.context(&a.input)
    })?;
    let (frames, _) = a.input.tracking.frames(
        &opened.processed,
        a.every,
        a.input.read.contact_threshold_m,
        &mut |_, _| {},
    );
    let (mut t_carried, mut t_scratch) = (Vec::new(), Vec::new());
    let (mut r_carried, mut r_scratch) = (Vec::new(), Vec::new());
    let mut bar = progress::bar("tracking twice", " frames", frames.len());
    for (i, &k) in frames.iter().enumerate() {
        for (tracker, times, rows) in [
            (&mut carried, &mut t_carried, &mut r_carried),
            (&mut scratch, &mut t_scratch, &mut r_scratch),
        ] {
            let t0 = Instant::now();
            let mut row = tracker.track(&opened.processed, k, &mut |_, _| true)?;
            times.push(t0.elapsed().as_secs_f64());
            let recorded = opened.recorded.get(k).copied().flatten();
            row.score(recorded.map(|p| (p.pose, p.press)), &opened.object.symmetry);
            rows.push(row);
        }
        let _ = kdam::BarExt::update_to(&mut bar, i + 1);
    }
    progress::finish(&mut bar);
    let carried = record("carried", &t_carried, &r_carried);
    let scratch = record("per_frame", &t_scratch, &r_scratch);
    let ratio = |key: &str| {
        carried[key].as_f64().unwrap_or(f64::NAN) / scratch[key].as_f64().unwrap_or(f64::NAN)
    };
    let compare = json!({
        "bench": "track", "recording": crate::path_json(&a.input.recording), "object": opened.object.name,
        "frames": frames.len(),
        "median_s_per_frame_ratio": ratio("median_s_per_frame"),
        "mean_position_err_ratio": ratio("mean_position_err_mm"),
    });
    for line in [carried, scratch, compare] {
        println!("{line}");
    }
    Ok(())
}
