//! `tnd-workbench`: the egui desktop workbench for tactile neural de-rendering.

use anyhow::Result;
use clap::Parser;
use tnd_workbench::app::WorkbenchApp;

/// Open the workbench on the bundled default scene.
#[derive(Parser)]
#[command(name = "tnd-workbench", version, about)]
struct Args {}

fn main() -> Result<()> {
    let _args = Args::parse();
    let options = eframe::NativeOptions {
        renderer: eframe::Renderer::Wgpu,
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1280.0, 800.0])
            .with_title("tactile-derender workbench"),
        ..Default::default()
    };
    eframe::run_native(
        "tactile-derender workbench",
        options,
        Box::new(|_cc| Ok(Box::new(WorkbenchApp::default()))),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the workbench window: {e}"))
}
