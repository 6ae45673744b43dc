//! Benchmark of the analysis tabs, driving the real app headlessly (egui_kittest, no GPU): every number is the wall
//! time of one UI frame (layout + tessellation, no rasterisation), the budget being 16 ms.
//!
//! * `grid`: open a dataset in the inspector and scroll its thumbnail grid down with the mouse wheel for N frames;
//!   reports frame times while scrolling, thumbnails decoded, and the time for the screen to fill after stopping.
//! * `sample`: de-render the default scene with a checkpoint (DDIM K steps, S samples) and time every frame while
//!   the sampler runs on its thread; reports frame times and the sampler's wall time.
//!
//! `cargo bench -p tnd-workbench --bench bench_panels -- grid DATASET_DIR [frames] [px_per_frame]`
//! `cargo bench -p tnd-workbench --bench bench_panels -- sample MODEL.safetensors [samples] [steps]`
//! `cargo bench -p tnd-workbench --bench bench_panels -- make-model OUT.safetensors` writes a randomly
//! initialised model of the default architecture (the shipped model's cost, not its quality) for `sample`.

use std::time::{Duration, Instant};

use egui_kittest::Harness;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::command::Command;
use tnd_workbench::state::{SamplerName, State, Tab};

fn harness(state: State) -> Harness<'static, WorkbenchApp> {
    Harness::builder()
        .with_size([1500.0, 940.0])
        .with_max_steps(1_000_000)
        .build_ui_state(
            |ui, app: &mut WorkbenchApp| app.show(ui),
            WorkbenchApp::with_state(state),
        )
}

/// Frame times, milliseconds (all of them: the app's own timings keep only the last 240).
#[derive(Default)]
struct Samples(Vec<f64>);

impl Samples {
    fn push(&mut self, ms: f64) {
        self.0.push(ms);
    }
    fn quantile(&self, q: f64) -> f64 {
        let mut v = self.0.clone();
        v.sort_by(f64::total_cmp);
        v.get(((q * (v.len().max(1) - 1) as f64).round()) as usize)
            .copied()
            .unwrap_or(0.0)
    }
}

fn timed_step(h: &mut Harness<'_, WorkbenchApp>, frames: &mut Samples) {
    let t0 = Instant::now();
    h.step();
    frames.push(t0.elapsed().as_secs_f64() * 1e3);
}

fn stats(s: &Samples) -> serde_json::Value {
    let over = s.0.iter().filter(|&&v| v > 16.0).count();
    serde_json::json!({"median_ms": s.quantile(0.5), "p90_ms": s.quantile(0.9), "p99_ms": s.quantile(0.99),
        "max_ms": s.quantile(1.0), "n": s.0.len(), "over_16ms": over})
}

fn grid(dir: &str, n_frames: usize, px: f32) {
    let mut state = State::default();
    state.view.tab = Tab::Dataset;
    state.dataset.path = Some(dir.into());
    let mut h = harness(state);
    let mut frames = Samples::default();
    let t0 = Instant::now();
    // First screen of thumbnails.
    loop {
        timed_step(&mut h, &mut frames);
        let ready = h
            .state()
            .analysis
            .dataset
            .as_ref()
            .is_some_and(|b| b.uploaded > 0 && b.missing == 0);
        if ready || t0.elapsed() > Duration::from_secs(60) {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let first_screen_ms = t0.elapsed().as_secs_f64() * 1e3;
    let pairs = h
        .state()
        .analysis
        .dataset
        .as_ref()
        .map_or(0, |b| b.dataset.len(h.state().state.dataset.split));
    let mut scrolling = Samples::default();
    let uploaded0 = h
        .state()
        .analysis
        .dataset
        .as_ref()
        .map_or(0, |b| b.uploaded);
    h.event(egui::Event::PointerMoved(egui::pos2(900.0, 300.0)));
    let t_scroll = Instant::now();
    for _ in 0..n_frames {
        h.event(egui::Event::MouseWheel {
            unit: egui::MouseWheelUnit::Point,
            delta: egui::vec2(0.0, -px),
            phase: egui::TouchPhase::Move,
            source: egui::MouseWheelSource::Unknown,
            modifiers: egui::Modifiers::NONE,
        });
        timed_step(&mut h, &mut scrolling);
    }
    let scroll_s = t_scroll.elapsed().as_secs_f64();
    let t_fill = Instant::now();
    let mut after = Samples::default();
    loop {
        timed_step(&mut h, &mut after);
        let done = h
            .state()
            .analysis
            .dataset
            .as_ref()
            .is_none_or(|b| b.missing == 0);
        if done || t_fill.elapsed() > Duration::from_secs(30) {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let b = h.state().analysis.dataset.as_ref();
    println!(
        "{}",
        serde_json::json!({
            "bench": "grid",
            "pairs_in_split": pairs,
            "first_screen_ms": first_screen_ms,
            "scroll_frames": stats(&scrolling),
            "scroll_px_per_frame": px,
            "scroll_wall_s": scroll_s,
            "thumbnails_decoded_while_scrolling": b.map_or(0, |b| b.uploaded) - uploaded0,
            "fill_after_stop_ms": t_fill.elapsed().as_secs_f64() * 1e3,
            "frames_after_stop": stats(&after),
            "thumbnails_cached": b.map_or(0, |b| b.cached()),
            "errors": h.state().errors,
        })
    );
}

fn sample(model: &str, samples: usize, steps: usize) {
    let mut state = State::default();
    state.view.tab = Tab::Derender;
    state.model.path = Some(model.into());
    state.derender.config.sampler.kind = SamplerName::Ddim;
    state.derender.config.sampler.steps = steps;
    state.derender.config.samples = samples;
    let mut h = harness(state);
    let t0 = Instant::now();
    while h.state().sim.is_none() && t0.elapsed() < Duration::from_secs(60) {
        h.step();
        std::thread::sleep(Duration::from_millis(2));
    }
    h.state_mut().apply(Command::RunDerender);
    let mut frames = Samples::default();
    let t_run = Instant::now();
    let mut n = 0usize;
    while h.state().analysis.derender.running && t_run.elapsed() < Duration::from_secs(600) {
        timed_step(&mut h, &mut frames);
        n += 1;
        // A 60 Hz display: the next frame in ~16 ms.
        std::thread::sleep(Duration::from_millis(16));
    }
    let run_s = t_run.elapsed().as_secs_f64();
    let mut shown = Samples::default();
    for _ in 0..20 {
        timed_step(&mut h, &mut shown);
    }
    let app = h.state();
    println!(
        "{}",
        serde_json::json!({
            "bench": "sample",
            "samples": samples,
            "ddim_steps": steps,
            "run_wall_s": run_s,
            "sampler_s": app.analysis.derender.result.as_ref().map(|r| r.seconds),
            "frames_while_sampling": stats(&frames),
            "frames_with_results_shown": stats(&shown),
            "frames": n,
            "errors": app.errors,
        })
    );
}

fn main() {
    // `cargo bench` appends `--bench` to the arguments.
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let arg = |i: usize| args.get(i).map(String::as_str);
    match (arg(0), arg(1)) {
        (Some("grid"), Some(dir)) => grid(
            dir,
            arg(2).and_then(|a| a.parse().ok()).unwrap_or(300),
            arg(3).and_then(|a| a.parse().ok()).unwrap_or(60.0),
        ),
        (Some("sample"), Some(model)) => sample(
            model,
            arg(2).and_then(|a| a.parse().ok()).unwrap_or(16),
            arg(3).and_then(|a| a.parse().ok()).unwrap_or(50),
        ),
        (Some("make-model"), Some(out)) => {
            let cfg = tactile_derender::model::UNet2DConfig::default();
            let made = tactile_derender::model::checkpoint::build(&cfg, &candle_core::Device::Cpu)
                .and_then(|vars| {
                    tactile_derender::model::init::init_params(&vars.varmap, 1)?;
                    tactile_derender::model::checkpoint::save_model(
                        std::path::Path::new(out),
                        &vars.varmap,
                        &cfg,
                        Default::default(),
                    )
                });
            match made {
                Ok(()) => println!("{out}"),
                Err(e) => eprintln!("{out}: {e}"),
            }
        }
        _ => eprintln!("usage: bench_panels grid DATASET_DIR [frames] [px] | sample MODEL [samples] [steps] | make-model OUT"),
    }
}
