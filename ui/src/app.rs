//! The workbench window: the default scene (a library object under the bubble) and its simulated images, updated
//! live as the user moves the sliders.

use egui::{Color32, TextureHandle, TextureOptions};
use tactile_derender::image::Image;
use tactile_derender::io::preview::{self, PanelStyle};
use tactile_derender::objects::ObjectSet;
use tactile_derender::sensor::{Scene, Se2};
use tactile_derender::sim::{PreparedObject, SimConfig, SimOutput, Simulator};

use crate::colormap::to_color_image;

/// What the user set: object, pose, press and inflation.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneState {
    pub object: String,
    pub pose: Se2,
    /// Press depth of the membrane apex into the object's top, metres.
    pub press: f64,
    /// Elastomer inflation height, metres.
    pub inflation: f64,
    pub seed: u64,
}

impl Default for SceneState {
    fn default() -> Self {
        Self {
            object: "cross_w12_s50".into(),
            pose: Se2::new(0.002, -0.001, 0.35),
            press: 0.006,
            inflation: 0.030,
            seed: 0,
        }
    }
}

/// The running app.
pub struct WorkbenchApp {
    pub state: SceneState,
    objects: ObjectSet,
    computed_for: Option<SceneState>,
    output: Option<SimOutput>,
    error: Option<String>,
    elapsed_ms: f64,
    textures: Vec<(String, TextureHandle, (f32, f32))>,
}

impl Default for WorkbenchApp {
    fn default() -> Self {
        let objects = ObjectSet::builtin();
        let mut state = SceneState::default();
        if objects.find(&state.object).is_none() {
            if let Some(first) = objects.entries().first() {
                state.object = first.name.clone();
            }
        }
        Self {
            state,
            objects,
            computed_for: None,
            output: None,
            error: None,
            elapsed_ms: 0.0,
            textures: Vec::new(),
        }
    }
}

impl WorkbenchApp {
    /// Number of pixels in contact in the current simulation (None before the first run or after an error).
    pub fn contact_pixels(&self) -> Option<usize> {
        self.output.as_ref().map(|o| o.contact_pixels)
    }

    /// Re-run the simulator when the scene changed.
    pub fn refresh(&mut self) {
        if self.computed_for.as_ref() == Some(&self.state) {
            return;
        }
        self.computed_for = Some(self.state.clone());
        let t0 = std::time::Instant::now();
        match self.simulate() {
            Ok(out) => {
                self.output = Some(out);
                self.error = None;
            }
            Err(e) => {
                self.output = None;
                self.error = Some(e);
            }
        }
        self.elapsed_ms = t0.elapsed().as_secs_f64() * 1e3;
        self.textures.clear();
    }

    fn simulate(&self) -> Result<SimOutput, String> {
        let mut cfg = SimConfig::default();
        cfg.elastomer.inflation = self.state.inflation;
        let sim = Simulator::new(cfg).map_err(|e| e.to_string())?;
        let mesh = self
            .objects
            .mesh(&self.state.object)
            .map_err(|e| e.to_string())?;
        let object = PreparedObject::new(mesh).map_err(|e| e.to_string())?;
        let scene = Scene {
            object: self.state.pose,
            sensor: sim.pressing_pose(&object, 0.0, 0.0, 0.0, self.state.press),
        };
        Ok(sim.simulate(&object, &scene, self.state.seed))
    }

    fn controls(&mut self, ui: &mut egui::Ui) {
        ui.heading("Scene");
        egui::ComboBox::from_label("Object")
            .selected_text(self.state.object.clone())
            .show_ui(ui, |ui| {
                for e in self.objects.entries() {
                    ui.selectable_value(&mut self.state.object, e.name.clone(), &e.name);
                }
            });
        let mut x_mm = self.state.pose.x * 1e3;
        let mut y_mm = self.state.pose.y * 1e3;
        let mut theta_deg = self.state.pose.theta.to_degrees();
        let mut press_mm = self.state.press * 1e3;
        let mut inflation_mm = self.state.inflation * 1e3;
        ui.add(egui::Slider::new(&mut x_mm, -30.0..=30.0).text("x (mm)"));
        ui.add(egui::Slider::new(&mut y_mm, -30.0..=30.0).text("y (mm)"));
        ui.add(egui::Slider::new(&mut theta_deg, -180.0..=180.0).text("θ (deg)"));
        ui.add(egui::Slider::new(&mut press_mm, 0.0..=20.0).text("press (mm)"));
        ui.separator();
        ui.heading("Elastomer");
        ui.add(egui::Slider::new(&mut inflation_mm, 10.0..=50.0).text("inflation (mm)"));
        ui.add(egui::DragValue::new(&mut self.state.seed).prefix("seed "));
        self.state.pose = Se2::new(x_mm * 1e-3, y_mm * 1e-3, theta_deg.to_radians());
        self.state.press = press_mm * 1e-3;
        self.state.inflation = inflation_mm * 1e-3;
        ui.separator();
        if let Some(n) = self.contact_pixels() {
            ui.label(format!("contact pixels: {n}"));
            ui.label(format!("simulated in {:.1} ms", self.elapsed_ms));
        }
        if let Some(e) = &self.error {
            ui.colored_label(Color32::RED, e);
        }
    }

    fn images(&mut self, ui: &mut egui::Ui) {
        let Some(out) = &self.output else {
            return;
        };
        if self.textures.is_empty() {
            let list: [(&str, &Image, bool); 6] = [
                ("D depth", &out.depth, true),
                ("E elastomer", &out.elastomer, true),
                ("M mask", &out.mask, false),
                ("X0 in-contact depth", &out.target, true),
                ("S signature", &out.signature, true),
                ("Y imprint", &out.imprint, false),
            ];
            for (name, img, zero_missing) in list {
                let style = PanelStyle {
                    zero_is_missing: zero_missing,
                    ..Default::default()
                };
                let range = preview::display_range(img, &style);
                let tex = ui.ctx().load_texture(
                    name,
                    to_color_image(img, range, zero_missing),
                    TextureOptions::NEAREST,
                );
                self.textures.push((name.to_string(), tex, range));
            }
        }
        ui.horizontal_wrapped(|ui| {
            for (name, tex, range) in &self.textures {
                ui.vertical(|ui| {
                    ui.label(name);
                    ui.image((tex.id(), egui::vec2(256.0, 256.0)));
                    ui.label(format!("{:.1} .. {:.1} mm", range.0 * 1e3, range.1 * 1e3));
                });
            }
        });
    }
}

impl eframe::App for WorkbenchApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        egui::Panel::left("controls").show(ui, |ui| self.controls(ui));
        self.refresh();
        egui::CentralPanel::default().show(ui, |ui| self.images(ui));
    }
}
