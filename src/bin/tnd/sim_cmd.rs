//! `tnd sim`: one simulated contact written as `.npy` arrays (metres) and PNG previews, with a JSON summary.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;
use serde_json::json;
use tactile_derender::image::Image;
use tactile_derender::io::{npy, preview};
use tactile_derender::sensor::Scene;
use tactile_derender::sim::{PreparedObject, SimOutput, Simulator};

use crate::args::SensorArgs;
use tactile_derender::pipeline::ObjectSpec;

#[derive(Args, Debug)]
pub struct SimArgs {
    #[command(flatten)]
    pub object: ObjectSpec,
    /// Object pose on the table relative to the sensor axis: X,Y,THETA (metres, metres, radians).
    #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
    pub pose: String,
    /// Press depth of the membrane apex below the object's top, metres.
    #[arg(long, default_value_t = tactile_derender::sim::DEFAULT_PRESS_M, allow_hyphen_values = true)]
    pub press: f64,
    /// Sensor yaw about the vertical, radians.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub sensor_yaw: f64,
    #[command(flatten)]
    pub sensor: SensorArgs,
    /// Seed of the signature noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub force: crate::args::ForceArg,
    #[command(flatten)]
    pub rerun: crate::rerun_out::RerunArgs,
}

/// The arrays written by `tnd sim` (and their preview titles).
pub const OUTPUTS: [(&str, &str); 7] = [
    ("depth", "D depth"),
    ("elastomer", "E elastomer"),
    ("mask", "M mask"),
    ("target", "X0 target"),
    ("signature", "S signature"),
    ("reference", "R reference"),
    ("imprint", "Y imprint"),
];

fn image_of<'a>(out: &'a SimOutput, name: &str) -> &'a Image {
    match name {
        "depth" => &out.depth,
        "elastomer" => &out.elastomer,
        "mask" => &out.mask,
        "target" => &out.target,
        "signature" => &out.signature,
        "reference" => &out.reference,
        _ => &out.imprint,
    }
}

pub fn run(a: SimArgs) -> Result<()> {
    let mesh = Path::new(&a.object.object);
    let mut inputs = a.sensor.inputs();
    inputs.push(mesh);
    let _out = crate::outputs::folder("--out", &a.out, a.force.force, &inputs)?;
    let pose = crate::args::parse_pose("--pose", &a.pose)?;
    crate::args::check_press("--press", a.press, false)?;
    if !a.sensor_yaw.is_finite() {
        anyhow::bail!(
            "--sensor-yaw must be a finite angle in radians, got {}",
            a.sensor_yaw
        );
    }
    let config = a.sensor.sim_config()?;
    let rrd = a.rerun.open("tnd sim", a.force.force, &inputs)?;
    let loaded = a.object.load()?;
    loaded.check_scale("a simulation")?;
    let (name, mesh) = (loaded.name, loaded.mesh);
    let sim = Simulator::new(config)?;
    let object = PreparedObject::new(mesh)?;
    let scene = Scene {
        object: pose,
        sensor: sim.pressing_pose(&object, 0.0, 0.0, a.sensor_yaw, a.press),
    };
    let (out, elapsed_s) = sim.simulate_timed(&object, &scene, a.seed);
    if out.contact_pixels == 0 {
        warn_no_contact("", &sim, &object, &scene);
    }

    for (file, title) in OUTPUTS {
        let img = image_of(&out, file);
        npy::write_image(&a.out.join(format!("{file}.npy")), img)?;
        let style = preview_style(file, title);
        preview::save_png(
            &a.out.join(format!("{file}.png")),
            &preview::render_panel(img, &style),
        )?;
    }
    let panels: Vec<_> = OUTPUTS
        .iter()
        .map(|(f, t)| preview::render_panel(image_of(&out, f), &preview_style(f, t)))
        .collect();
    let caption = vec![format!(
        "{name}  pose x={:.1}mm y={:.1}mm theta={:.1}deg  press={:.1}mm  contact={} px  seed={}",
        pose.x * 1e3,
        pose.y * 1e3,
        pose.theta.to_degrees(),
        a.press * 1e3,
        out.contact_pixels,
        a.seed
    )];
    preview::save_png(
        &a.out.join("overview.png"),
        &preview::side_by_side(&panels, &caption),
    )?;

    if let Some(log) = &rrd {
        use crate::rerun_out::{camera_views, object_at, TRUTH_RGB};
        log.set_step("frame", 0);
        object_at(log, "world/object", &object.mesh, pose, TRUTH_RGB)?;
        log.mesh(
            "world/membrane",
            sim.elastomer_mesh(),
            &scene.sensor.t_world_sensor(),
            [200, 200, 200],
        )?;
        let images: Vec<(&str, &Image)> = OUTPUTS
            .iter()
            .map(|(f, _)| (*f, image_of(&out, f)))
            .collect();
        camera_views(
            log,
            sim.intrinsics(),
            &sim.t_world_camera(&scene.sensor),
            &images,
            Some(("contact", &out.target)),
        )?;
    }
    let rerun = crate::rerun_out::finish(rrd)?;
    let range = |img: &Image, nonzero: bool| {
        img.range_where(|x| !nonzero || x != 0.0)
            .map(|(lo, hi)| json!([lo, hi]))
            .unwrap_or(serde_json::Value::Null)
    };
    let summary = json!({
        "object": name,
        "pose": [pose.x, pose.y, pose.theta],
        "press_m": a.press,
        "seed": a.seed,
        "resolution": [out.depth.width, out.depth.height],
        "contact_pixels": out.contact_pixels,
        "depth_range_m": range(&out.depth, true),
        "elastomer_range_m": range(&out.elastomer, true),
        "target_range_m": range(&out.target, true),
        "signature_range_m": range(&out.signature, true),
        "imprint_range_m": range(&out.imprint, false),
        "sensor_position_m": scene.sensor.position,
        "elapsed_s": elapsed_s,
        "out": crate::path_json(&a.out),
        "rerun": rerun.as_deref().map(crate::path_json),
    });
    println!("{summary}");
    Ok(())
}

/// Preview style per output: masks 0..1 without "missing" pixels, imprints signed around 0, depths in mm.
pub fn preview_style(file: &str, title: &str) -> preview::PanelStyle {
    match file {
        "mask" => preview::PanelStyle {
            title: title.into(),
            range_m: Some((0.0, 1.0)),
            zero_is_missing: false,
            millimetres: false,
            ..Default::default()
        },
        "imprint" => preview::PanelStyle {
            title: title.into(),
            zero_is_missing: false,
            ..Default::default()
        },
        _ => preview::PanelStyle {
            title: title.into(),
            ..Default::default()
        },
    }
}

/// Says on stderr that `scene` touches nothing (`what`: where, e.g. "in any frame"), with where the object lies from
/// the membrane and the `--pose` that would centre it.
pub fn warn_no_contact(what: &str, sim: &Simulator, object: &PreparedObject, scene: &Scene) {
    let hint = sim.contact_hint(object, scene);
    let c = hint.centred;
    eprintln!(
        "warning: no contact{what}: {hint}{}",
        if hint.press_m > 0.0 {
            format!(" (--pose {:.4},{:.4},{:.4})", c.x, c.y, c.theta)
        } else {
            String::new()
        }
    );
}
