//! `tnd-workbench`: the egui desktop workbench for tactile neural de-rendering.

use std::path::PathBuf;

use anyhow::{anyhow, Result};
use clap::Parser;
use tactile_derender::mesh::Units;
use tactile_derender::objects::inspect::likely_units;
use tnd_workbench::app::{Launch, ScreenshotSlot, WorkbenchApp};
use tnd_workbench::view3d::gpu::DEPTH_BITS;

/// Open the workbench (on the last session, or the bundled default scene).
#[derive(Parser)]
#[command(name = "tnd-workbench", version, about)]
struct Args {
    /// Open this session file (sessions/*.json) instead of the last session.
    #[arg(long)]
    session: Option<PathBuf>,
    /// Render the window once into this PNG and exit (documentation, bug reports, tests).
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Draw the 3D view on the CPU instead of with wgpu (the fallback used where wgpu is missing).
    #[arg(long)]
    cpu_3d: bool,
    /// Print the update, simulation, UI and frame timings (median, p90) as JSON lines.
    #[arg(long)]
    timings: bool,
    /// Present frames without waiting for vertical sync (frame-time measurements).
    #[arg(long)]
    no_vsync: bool,
    /// Start a de-rendering run with the session's settings once the scene is simulated (screenshots of the
    /// De-render tab, frame timings while sampling).
    #[arg(long)]
    run_derender: bool,
    /// Run de-rendering, then register its samples (Pose tab screenshots).
    #[arg(long)]
    run_pose: bool,
    /// Put this mesh file (OBJ, STL, PLY, glTF/GLB) in the scene, over the session's object.
    #[arg(long, value_name = "MESH")]
    object: Option<PathBuf>,
    /// Units of --object (m, cm, mm or metres per unit); default: metres, or the unit its size says (as `tnd objects
    /// import` guesses).
    #[arg(long, requires = "object")]
    units: Option<Units>,
    /// Use this sensor file (JSON, e.g. from `tnd calibrate --out`) instead of the session's sensor.
    #[arg(long, value_name = "FILE")]
    sensor: Option<PathBuf>,
}

/// `--units`, or the unit that makes `path`'s size plausible (metres when it already is, or when it cannot be read:
/// the workbench then shows the load error).
fn object_units(path: &std::path::Path, units: Option<Units>) -> Units {
    units.unwrap_or_else(|| {
        let options = tactile_derender::mesh::LoadOptions {
            units: Units::M,
            fit_to_size: None,
        };
        tactile_derender::mesh::load(path, &options)
            .ok()
            .and_then(|m| likely_units(m.largest_extent(), Units::M))
            .unwrap_or(Units::M)
    })
}

fn main() -> std::process::ExitCode {
    match run(Args::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", tactile_derender::error::render_anyhow(&e));
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> Result<()> {
    // Files named on the command line are checked before a window opens, so that a typo fails like any command
    // (a screenshot run would otherwise save the default scene and exit 0).
    for (flag, path) in [("--session", &args.session), ("--object", &args.object)] {
        if let Some(p) = path {
            if !p.is_file() {
                return Err(anyhow!("{flag} {}: no such file", p.display()));
            }
        }
    }
    // A session that does not load fails here too (the window would otherwise open on the default scene with the
    // error in its status bar, and a screenshot run would exit 0).
    if let Some(p) = &args.session {
        tnd_workbench::session::read(p)?;
    }
    let sensor = args
        .sensor
        .as_deref()
        .map(tactile_derender::sim::sensor_file::load)
        .transpose()?;
    // The model's process-wide settings, the same as `tnd`'s (before any thread starts); a variable the user set is
    // kept.
    let kernels = tactile_derender::model::kernels::KernelSettings::default();
    for (name, value) in kernels.environment() {
        if std::env::var_os(name).is_none() {
            std::env::set_var(name, value);
        }
    }
    kernels.apply_allocator_policy();
    let shooting = args.screenshot.is_some();
    let mut options = eframe::NativeOptions {
        renderer: eframe::Renderer::Wgpu,
        depth_buffer: DEPTH_BITS,
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1500.0, 940.0])
            .with_title("tactile-derender workbench"),
        persist_window: !shooting,
        ..Default::default()
    };
    if args.no_vsync {
        options.wgpu_options.surface.present_mode = eframe::wgpu::PresentMode::AutoNoVsync;
    }
    let slot: ScreenshotSlot = Default::default();
    let screenshot = args.screenshot.clone().map(|out| (out, slot.clone()));
    let object = args.object.clone().map(|p| {
        let units = object_units(&p, args.units);
        (p, units)
    });
    eframe::run_native(
        "tnd-workbench",
        options,
        Box::new(move |cc| {
            let launch = Launch {
                session: args.session,
                screenshot,
                cpu_3d: args.cpu_3d,
                print_timings: args.timings,
                run_derender: args.run_derender,
                run_pose: args.run_pose,
                object,
                sensor,
            };
            Ok(Box::new(WorkbenchApp::new(cc, launch)))
        }),
    )
    .map_err(|e| {
        anyhow!("cannot open the workbench window (is there a display and a GPU/Mesa driver?): {e}")
    })?;
    if let Some(out) = args.screenshot {
        let result = slot.lock().ok().and_then(|s| s.clone());
        match result {
            Some(Ok(())) => println!("{}", out.display()),
            Some(Err(e)) => return Err(anyhow!("screenshot {}: {e}", out.display())),
            None => {
                return Err(anyhow!(
                    "the window closed before the screenshot {} was taken",
                    out.display()
                ))
            }
        }
    }
    Ok(())
}
