//! Benchmark of the live update: drive the real app headlessly (egui_kittest, no GPU) and move the press slider N
//! times; for each move, time from the slider event until the new images are on screen (worker simulation + message
//! + texture upload), and time every UI frame (layout + tessellation, no rasterisation). Prints one JSON line.
//!
//! `cargo bench -p tnd-workbench --bench bench_update -- [moves] [resolution] [press|inflation]`
//! (moving the inflation rebuilds the membrane, its signed distance and E on every move).

use std::time::{Duration, Instant};

use egui::accesskit::Role;
use egui_kittest::kittest::Queryable;
use egui_kittest::Harness;
use tnd_workbench::app::WorkbenchApp;
use tnd_workbench::state::State;
use tnd_workbench::timings::Samples;

fn main() {
    // `cargo bench` appends `--bench` to the arguments.
    let mut args = std::env::args().skip(1).filter(|a| a != "--bench");
    let moves: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(100);
    let res: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(64);
    let slider = args.next().unwrap_or_else(|| "press".into());
    let (label, lo, step) = match slider.as_str() {
        "inflation" => ("inflation (mm)", 26.0, 0.5),
        _ => ("press (mm)", 3.0, 0.25),
    };
    let mut state = State::default();
    state.sim.camera.resolution = (res, res);
    let mut h = Harness::builder()
        .with_size([1500.0, 940.0])
        .with_max_steps(1_000_000)
        .build_ui_state(
            |ui, app: &mut WorkbenchApp| app.show(ui),
            WorkbenchApp::with_state(state),
        );
    let (mut update, mut frame) = (Samples::default(), Samples::default());
    let wait = |h: &mut Harness<'_, WorkbenchApp>, frame: &mut Samples| {
        let t0 = Instant::now();
        loop {
            let f0 = Instant::now();
            h.step();
            frame.push(f0.elapsed().as_secs_f64() * 1e3);
            if !h.state().busy() || t0.elapsed() > Duration::from_secs(30) {
                break;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    };
    wait(&mut h, &mut frame);
    let mut contact = Vec::new();
    for i in 0..moves {
        let value_mm = lo + (i % 20) as f64 * step;
        let t0 = Instant::now();
        h.get_by_role_and_label(Role::Slider, label)
            .set_value_accesskit(value_mm);
        wait(&mut h, &mut frame);
        update.push(t0.elapsed().as_secs_f64() * 1e3);
        contact.push(h.state().contact_pixels().unwrap_or(0));
    }
    let t = &h.state().timings;
    println!(
        "{}",
        serde_json::json!({
            "bench": "workbench_update",
            "slider": label,
            "resolution": [res, res],
            "moves": moves,
            "update_ms": {"median": update.median(), "p90": update.quantile(0.9), "max": update.quantile(1.0)},
            "simulate_ms": {"median": t.simulate.median(), "p90": t.simulate.quantile(0.9)},
            "ui_frame_ms": {"median": frame.median(), "p90": frame.quantile(0.9)},
            "contact_pixels_range": [contact.iter().min(), contact.iter().max()],
            "errors": h.state().errors,
        })
    );
}
