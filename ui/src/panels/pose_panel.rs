//! Pose tab (paper IV.C registration, V.D uncertainty): register the de-rendering samples (and the threshold
//! baseline) to the object, then show a top view with the object's outline at the true and estimated poses and the
//! contact points, the registration hypotheses with their costs, and KDE curves of the position and yaw errors over
//! the samples with the baseline's errors as points; hovering a curve highlights the nearest sample. The numbers
//! export as CSV and the plot as PNG (the evaluation stage's `samples.csv`, `kde.csv`, `uncertainty.png`).

use egui::Color32;
use egui_plot::{Legend, Line, Plot, PlotPoints, Points, VLine};

use crate::app::WorkbenchApp;
use crate::command::Command;
use crate::pose_view::{placed_mm, PoseAnalysis};

const TRUE_COLOUR: Color32 = Color32::from_rgb(90, 200, 90);
const ESTIMATE_COLOUR: Color32 = Color32::from_rgb(240, 150, 40);
const BASELINE_COLOUR: Color32 = Color32::from_rgb(230, 70, 70);
const HIGHLIGHT_COLOUR: Color32 = Color32::from_rgb(80, 170, 255);
const MULTI_COLOUR: Color32 = Color32::from_rgb(190, 110, 240);
const KDE_COLOUR: Color32 = Color32::from_rgb(200, 200, 210);

pub fn show(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let pose = &app.analysis.pose;
    let has_samples = app.analysis.derender.result.is_some();
    ui.horizontal(|ui| {
        if pose.running {
            if ui.button("Cancel registration").clicked() {
                cmds.push(Command::CancelPose);
            }
            match pose.progress {
                Some((done, total)) => {
                    ui.add(
                        egui::ProgressBar::new(done as f32 / total.max(1) as f32)
                            .desired_width(220.0)
                            .text(format!("{done} / {total}")),
                    );
                    // The step in progress, by name (the last one, the multi-sample estimate, is the longest).
                    let samples = app
                        .analysis
                        .derender
                        .result
                        .as_ref()
                        .map_or(0, |r| r.samples.len());
                    ui.label(tactile_derender::pipeline::pose_stage(done, samples));
                }
                None => {
                    ui.label("registering the samples…");
                }
            }
        } else if ui
            .add_enabled(has_samples, egui::Button::new("Register samples"))
            .on_disabled_hover_text(
                "run de-rendering first: its samples are what this tab registers",
            )
            .clicked()
        {
            cmds.push(Command::RunPose);
        }
        if !pose.running {
            let mut settings = app.state.pose.clone();
            ui.checkbox(&mut settings.check_signature, "signature check").on_hover_text(
                "judge the registration's hypotheses by the signature each one predicts (object rendered at the \
                 pose, contact, tactile shadow) against the measured one, and refine the best; off: the \
                 registration's lowest-cost hypothesis is the estimate. Applies to the next registration.",
            );
            let check = settings.check_signature;
            ui.add_enabled(check, egui::Checkbox::new(&mut settings.imprint_proposals, "imprint proposals"))
                .on_hover_text(
                    "also register the imprint's own thresholded contact and let the signature check judge its \
                     hypotheses beside the sample's (on small or shallow contacts the imprint can say more than \
                     one sample); off: only the sample's. Applies to the next registration.",
                );
            ui.add_enabled(
                check,
                egui::Checkbox::new(&mut settings.signature_check.native, "native-pixel check"),
            )
            .on_hover_text(
                "for a frame brought down from the camera's native pixels (a recording's frame, an imported pair, a \
                 native .npy), predict its signature at native pixels and resample it as the frame was: more \
                 accurate, up to twice as slow; off: one ray per model pixel. Frames made at the model's \
                 resolution always use one ray per pixel. Applies to the next registration.",
            );
            if settings != app.state.pose {
                cmds.push(Command::SetPose(Box::new(settings)));
            }
        }
        if pose.result.is_some()
            && ui
                .button("Export CSV, figures, PLY")
                .on_hover_text(
                    "samples.csv, kde.csv, the uncertainty and SE(2) fit figures (SVG and 2400 x 1000 PNG) and \
                     the geometry as PLY (contact, free-space and \
                     consensus points; the object at each estimate and the true pose; world frame, metres) in \
                     <export folder>/pose",
                )
                .clicked()
        {
            cmds.push(Command::ExportPose);
        }
        if pose.running {
            ui.spinner();
        }
    });
    let Some(r) = pose.result.as_ref() else {
        match &app.analysis.derender.result {
            _ if pose.running => ui.weak("The fits appear here when the registration is done."),
            Some(d) => ui.label(format!(
                "{} samples of {} ready to register.",
                d.samples.len(),
                d.input.label
            )),
            None => ui.weak("Run de-rendering first: its samples are what this tab registers."),
        };
        return;
    };
    let mut highlight = pose.highlight;
    let half = (ui.available_height() * 0.5).max(200.0);
    ui.horizontal(|ui| {
        ui.vertical(|ui| {
            ui.set_width((ui.available_width() * 0.55).max(300.0));
            top_view(ui, r, highlight, half);
        });
        ui.vertical(|ui| hypotheses(ui, r));
    });
    ui.horizontal(|ui| {
        // The two KDEs, and the circular θ histogram (square) where θ has errors.
        let rose = r.report.samples.iter().any(|s| s.theta_deg.is_some());
        let h = ui.available_height().max(180.0);
        let square = if rose {
            h.min(ui.available_width() / 4.0)
        } else {
            0.0
        };
        let w = (ui.available_width() - square) / 2.0 - 8.0;
        ui.vertical(|ui| {
            ui.set_width(w);
            kde_plot(ui, r, false, &mut highlight);
        });
        ui.vertical(|ui| {
            ui.set_width(w);
            kde_plot(ui, r, true, &mut highlight);
        });
        if rose {
            ui.vertical(|ui| {
                ui.set_width(square);
                rose_plot(ui, r);
            });
        }
    });
    if highlight != pose.highlight {
        cmds.push(Command::HighlightSample(highlight));
    }
}

/// One outline of the top view: legend name, colour, line width and its polylines placed in the world, mm.
type Placed<'a> = (&'a str, Color32, f32, Vec<Vec<[f64; 2]>>);

fn top_view(ui: &mut egui::Ui, r: &PoseAnalysis, highlight: Option<usize>, height: f32) {
    // Every outline drawn, placed once.
    let mut outlines: Vec<Placed<'_>> = Vec::new();
    for (k, s) in r.report.samples.iter().enumerate() {
        let bold = highlight.is_some() && highlight == r.sample_of(k);
        let (name, colour, width) = if bold {
            ("highlighted sample", HIGHLIGHT_COLOUR, 2.5)
        } else {
            (
                "sample estimates",
                ESTIMATE_COLOUR.gamma_multiply(0.35),
                1.0,
            )
        };
        outlines.push((name, colour, width, placed_mm(&r.outline, &s.pose)));
    }
    if let Some(best) = r.single_estimate() {
        let name = if r.checked_from_imprint {
            "single-sample estimate (signature-checked; the imprint's proposal)"
        } else if r.checked.is_some() {
            "single-sample estimate (signature-checked)"
        } else {
            "best hypothesis"
        };
        outlines.push((name, ESTIMATE_COLOUR, 2.0, placed_mm(&r.outline, &best)));
    }
    if let Some(m) = &r.report.multi_sample {
        let placed = placed_mm(&r.outline, &m.pose);
        outlines.push(("multi-sample estimate", MULTI_COLOUR, 2.0, placed));
    }
    if let Some(b) = &r.report.baseline {
        outlines.push((
            "baseline",
            BASELINE_COLOUR,
            1.5,
            placed_mm(&r.outline, &b.pose),
        ));
    }
    if let Some(t) = &r.truth {
        outlines.push(("true pose", TRUE_COLOUR, 2.0, placed_mm(&r.outline, t)));
    }
    let contacts: Vec<[f64; 2]> = r
        .contacts
        .iter()
        .map(|c| [c[0] * 1e3, c[1] * 1e3])
        .collect();
    // Room above the drawing for the legend (top right), so that it covers no outline: the drawing's extent,
    // raised by 45 % of its height (the equal-aspect view then widens or heightens around it).
    let points = || {
        outlines
            .iter()
            .flat_map(|o| o.3.iter().flatten())
            .chain(&contacts)
    };
    let span = |k: usize| {
        points().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p[k]), b.max(p[k]))
        })
    };
    let ((x0, x1), (y0, y1)) = (span(0), span(1));
    let mut plot = Plot::new("pose_top_view")
        .height(height)
        .data_aspect(1.0)
        .x_axis_label("world x (mm)")
        .y_axis_label("world y (mm)")
        .legend(Legend::default());
    if x0 < x1 && y0 < y1 {
        plot = plot
            .include_x(x0)
            .include_x(x1)
            .include_y(y0)
            .include_y(y1 + 0.45 * (y1 - y0).max(0.3 * (x1 - x0)));
    }
    plot.show(ui, |p| {
        for (name, colour, width, lines) in outlines {
            for l in lines {
                p.line(
                    Line::new(name, PlotPoints::from(l))
                        .color(colour)
                        .width(width),
                );
            }
        }
        if let Some(post) = &r.posterior {
            let name = format!("posterior, 90 % regions ({} modes)", post.modes.len());
            for m in &post.modes {
                let mut ring: Vec<[f64; 2]> = m
                    .ellipse_xy(0.9, 64)
                    .iter()
                    .map(|[x, y]| [x * 1e3, y * 1e3])
                    .collect();
                ring.extend(ring.first().copied());
                p.line(
                    Line::new(name.as_str(), PlotPoints::from(ring))
                        .color(POSTERIOR_COLOUR)
                        .width(1.0 + 2.5 * m.weight as f32),
                );
            }
        }
        p.points(
            Points::new(
                format!("contact points (sample {})", r.registered_sample),
                PlotPoints::from(contacts),
            )
            .radius(1.5)
            .color(Color32::LIGHT_GRAY),
        );
    });
}

/// Colour of the posterior's regions in the top view.
const POSTERIOR_COLOUR: Color32 = Color32::from_rgb(0, 170, 190);

/// The registration of the chosen sample: ambiguity warnings, the posterior, the press and the depth anchoring, the
/// signature check, the hypotheses with their costs, the true pose, and the errors over all samples.
fn hypotheses(ui: &mut egui::Ui, r: &PoseAnalysis) {
    ui.strong(format!(
        "{}: hypotheses of sample {} (best first)",
        r.object, r.registered_sample
    ));
    ambiguity_warnings(ui, r);
    super::pose_posterior::posterior_summary(ui, r);
    press_and_anchor(ui, r);
    signature_check(ui, r);
    hypotheses_grid(ui, r);
    if let Some(t) = &r.truth {
        ui.label(format!(
            "true pose: x {:.2} mm, y {:.2} mm, θ {:.1}°",
            t.x * 1e3,
            t.y * 1e3,
            t.theta.to_degrees()
        ));
    }
    registration_errors(ui, r);
}

/// Warnings when the samples split between poses or the signature fits a rival pose about as well.
fn ambiguity_warnings(ui: &mut egui::Ui, r: &PoseAnalysis) {
    let modes = r.report.major_modes();
    if modes.len() > 1 {
        let list: Vec<String> = modes.iter().map(|m| m.describe()).collect();
        ui.colored_label(
            ui.visuals().warn_fg_color,
            format!("ambiguous: the samples split between {} poses ({})", modes.len(), list.join("; ")),
        )
        .on_hover_text(
            "Each holds at least a quarter of the registered samples: the contact fits the object either way (a flat \
             face, two similar ends). The estimate is one of them; the KDE below shows the split.",
        );
    }
    if let Some(rival) = r.signature_rival.filter(|v| v.ambiguous()) {
        ui.colored_label(
            ui.visuals().warn_fg_color,
            format!("ambiguous: the signature fits another pose about as well ({})", rival.describe()),
        )
        .on_hover_text(
            "The signature check scored a second pose, more than 2 mm or 15° from the estimate (the object's symmetry \
             aside), within 4 nats of log-likelihood of it: the measured signature cannot tell the two apart, and \
             the sensor's noise decides which one is picked.",
        );
    }
}

/// The press found from the samples (recordings without a pose) and the sample's contact depths' offset.
fn press_and_anchor(ui: &mut egui::Ui, r: &PoseAnalysis) {
    if let Some(p) = r.press_found_m {
        ui.label(format!("press {:.2} mm, found from the samples", p * 1e3))
            .on_hover_text(
                "The recording gives no pose, so nothing says how deep the sensor was pressed: the press is the one \
                 whose registered pose best explains the signature, from the samples' highest contact point on the \
                 object's top to 6 mm deeper (as `tnd recording track` and `tnd pose --press auto`).",
            );
    }
    if let Some(&shift) = r.anchor_shift_m.get(r.registered_sample) {
        ui.label(if shift == 0.0 {
            "contact depths as generated (no offset to the signature to correct)".to_string()
        } else {
            format!("contact depths anchored to the signature: {:+.2} mm", shift * 1e3)
        })
        .on_hover_text(
            "The sample's contact depths were moved by the median difference to the measured signature before \
             registration (a drifted membrane inflation offsets them all alike).",
        );
    }
}

/// The signature check's estimate, its distance to the truth and which proposal won.
fn signature_check(ui: &mut egui::Ui, r: &PoseAnalysis) {
    if let Some(c) = r.checked {
        let error = r
            .truth
            .map(|t| {
                format!(
                    " ({:.2} mm from the true position)",
                    (c.x - t.x).hypot(c.y - t.y) * 1e3
                )
            })
            .unwrap_or_default();
        let source = if r.checked_from_imprint {
            " — the imprint's proposal"
        } else {
            " — the sample's proposal"
        };
        ui.label(format!(
            "signature check: x {:.2} mm, y {:.2} mm, θ {:.1}°{error}{source}",
            c.x * 1e3,
            c.y * 1e3,
            c.theta.to_degrees()
        ))
        .on_hover_text(
            "Each hypothesis predicts the signature the sensor would have measured (object rendered at that pose, \
             contact where it reaches past the membrane, tactile shadow); the best explanation of the measured \
             signature is refined and drawn as the single-sample estimate. The hypotheses are the sample's \
             (listed below) and the imprint's threshold contact's, registered the same way: on small or shallow \
             contacts the imprint can say more than one sample.",
        );
    }
}

/// The registered sample's hypotheses, best first: pose and cost, in a scrolled grid.
fn hypotheses_grid(ui: &mut egui::Ui, r: &PoseAnalysis) {
    egui::ScrollArea::vertical()
        .id_salt("hypotheses")
        .max_height(260.0)
        .show(ui, |ui| {
            egui::Grid::new("hypotheses_grid")
                .striped(true)
                .show(ui, |ui| {
                    for h in ["#", "x (mm)", "y (mm)", "θ (deg)", "cost"] {
                        ui.strong(h);
                    }
                    ui.end_row();
                    for (i, h) in r.hypotheses.iter().enumerate() {
                        ui.label(i.to_string());
                        ui.label(format!("{:.2}", h.pose.x * 1e3));
                        ui.label(format!("{:.2}", h.pose.y * 1e3));
                        ui.label(format!("{:.1}", h.pose.theta.to_degrees()));
                        ui.label(format!("{:.4e}", h.cost));
                        ui.end_row();
                    }
                });
        });
}

/// The errors over the registered samples, of the multi-sample estimate and of the baseline, and what failed.
fn registration_errors(ui: &mut egui::Ui, r: &PoseAnalysis) {
    let rep = &r.report;
    let n = rep.samples.len().max(1) as f64;
    let mean_pos = rep.samples.iter().map(|s| s.position_mm).sum::<f64>() / n;
    let thetas: Vec<f64> = rep.samples.iter().filter_map(|s| s.theta_deg).collect();
    let theta = if thetas.is_empty() {
        "θ excluded (continuous symmetry)".to_string()
    } else {
        format!(
            "mean |θ error| {:.1}°",
            thetas.iter().map(|t| t.abs()).sum::<f64>() / thetas.len() as f64
        )
    };
    ui.label(format!(
        "{} of {} samples registered: mean position error {mean_pos:.2} mm, {theta}",
        rep.samples.len(),
        r.sample_index.len().max(rep.samples.len())
    ));
    if let Some(m) = &rep.multi_sample {
        ui.label(format!(
            "multi-sample estimate (consensus of {} samples): position error {:.2} mm{}",
            r.sample_index.len().max(rep.samples.len()),
            m.position_mm,
            m.theta_deg
                .map(|t| format!(", θ error {t:.1}°"))
                .unwrap_or_default()
        ))
        .on_hover_text(
            "the pixels at least half of the samples mark as contact, at their median depth, registered from \
             K random starts; with the signature check every sample is registered from them too and the \
             hypothesis that best explains the measured signature wins (the De-render tab shows the consensus and \
             the per-pixel contact probability)",
        );
    }
    match &rep.baseline {
        Some(b) => ui.label(format!(
            "baseline: position error {:.2} mm{}",
            b.position_mm,
            b.theta_deg
                .map(|t| format!(", θ error {t:.1}°"))
                .unwrap_or_default()
        )),
        None => ui.weak("baseline: no contact above the threshold"),
    };
    for f in &rep.failed {
        ui.colored_label(
            ui.visuals().warn_fg_color,
            format!("{} not registered: {}", f.what, f.reason),
        );
    }
}

/// Grid steps from the 1-2-5 series, each dividing the next (1, 2, 10 · 10^k; 2, 10, 20; 5, 10, 50): egui_plot's
/// default powers of ten leave an axis spanning a few millimetres with one label ("0"), its 1 mm steps too close to
/// label and its 10 mm steps outside the range.
fn steps_1_2_10(input: egui_plot::GridInput) -> [f64; 3] {
    let base = input.base_step_size.abs().max(f64::MIN_POSITIVE);
    let decade = 10f64.powf(base.log10().floor());
    // Per leading digit of the finest step: the three steps, in decades.
    let series = [
        [1.0, 2.0, 10.0],
        [2.0, 10.0, 20.0],
        [5.0, 10.0, 50.0],
        [10.0, 20.0, 100.0],
    ];
    let k = [1.0, 2.0, 5.0]
        .iter()
        .position(|m| m * decade >= base)
        .unwrap_or(3);
    series[k].map(|m| m * decade)
}

/// A tick label with as many decimals as its step needs: egui_plot's default rounds the decimals of a 0.5 or 0.2 step
/// to none (labels "0 0 1 1 2 2" for 0, 0.5, 1, ...), since it expects powers of ten.
fn step_label(mark: egui_plot::GridMark, _range: &std::ops::RangeInclusive<f64>) -> String {
    let step = mark.step_size.abs().max(1e-12);
    let decimals = (-step.log10() - 1e-9).ceil().max(0.0) as usize;
    format!("{:.*}", decimals, mark.value)
}

/// KDE of the position (mm) or yaw (degrees) errors, the samples as a rug, the baseline as a point; hovering picks
/// the nearest sample.
fn kde_plot(ui: &mut egui::Ui, r: &PoseAnalysis, theta: bool, highlight: &mut Option<usize>) {
    let rep = &r.report;
    let value = |s: &tactile_derender::uncertainty::SampleError| {
        if theta {
            s.theta_deg
        } else {
            Some(s.position_mm)
        }
    };
    let (id, label, curve) = if theta {
        ("kde_theta", "θ error (deg)", &rep.theta_kde)
    } else {
        ("kde_position", "position error (mm)", &rep.position_kde)
    };
    let curve: Vec<[f64; 2]> = curve.iter().map(|&(x, d)| [x, d]).collect();
    let rug: Vec<[f64; 2]> = rep
        .samples
        .iter()
        .filter_map(|s| value(s).map(|v| [v, 0.0]))
        .collect();
    if theta && rug.is_empty() {
        ui.weak("θ error: excluded for this object's continuous symmetry");
        return;
    }
    let shown = highlight.and_then(|i| {
        let k = r.sample_index.iter().position(|&j| j == i)?;
        rep.samples.get(k).and_then(value)
    });
    let response = Plot::new(id)
        .height(ui.available_height().max(180.0))
        .x_axis_label(label)
        .x_grid_spacer(egui_plot::uniform_grid_spacer(steps_1_2_10))
        .x_axis_formatter(step_label)
        .y_axis_label("density")
        .legend(Legend::default())
        .show(ui, |p| {
            p.line(
                Line::new("KDE over samples", PlotPoints::from(curve))
                    .color(KDE_COLOUR)
                    .width(2.0),
            );
            p.points(
                Points::new("samples", PlotPoints::from(rug))
                    .radius(3.0)
                    .color(ESTIMATE_COLOUR),
            );
            if let Some(b) = rep.baseline.as_ref().and_then(value) {
                p.points(
                    Points::new("baseline", PlotPoints::from(vec![[b, 0.0]]))
                        .radius(6.0)
                        .shape(egui_plot::MarkerShape::Diamond)
                        .color(BASELINE_COLOUR),
                );
            }
            // The poses reported, against the samples they came from.
            if let Some(v) = rep.estimate.as_ref().and_then(value) {
                p.vline(VLine::new("single-sample estimate", v).color(ESTIMATE_COLOUR));
            }
            if let Some(v) = rep.multi_sample.as_ref().and_then(value) {
                p.vline(VLine::new("multi-sample estimate", v).color(MULTI_COLOUR));
            }
            if let Some(v) = shown {
                p.vline(VLine::new("highlighted sample", v).color(HIGHLIGHT_COLOUR));
            }
            p.pointer_coordinate()
        });
    // Name the plot for screen readers (and for tests, which hover it by this label).
    let name = format!("{label} KDE");
    response
        .response
        .widget_info(|| egui::WidgetInfo::labeled(egui::accesskit::Role::Figure, true, &name));
    // `pointer_coordinate` is the pointer anywhere on screen in this plot's coordinates: only act while it is over
    // this plot (else the other KDE plot's answer is overwritten every frame).
    if let Some(pos) = response
        .inner
        .filter(|_| response.response.contains_pointer())
    {
        *highlight = rep
            .samples
            .iter()
            .enumerate()
            .filter_map(|(k, s)| value(s).map(|v| (k, (v - pos.x).abs())))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .and_then(|(k, _)| r.sample_of(k));
    }
}

/// The samples' θ errors as a circular histogram ([`tactile_derender::uncertainty::rose`]): the symmetry period once
/// round, no error at the top, wedge areas by share, the estimates as rays.
fn rose_plot(ui: &mut egui::Ui, r: &PoseAnalysis) {
    use tactile_derender::uncertainty::rose::{rose_point, rose_wedges};
    let rep = &r.report;
    let period = rep.theta_period_deg.unwrap_or(360.0);
    let errors: Vec<f64> = rep.samples.iter().filter_map(|s| s.theta_deg).collect();
    let half = period / 2.0;
    let response = Plot::new("rose_theta")
        .data_aspect(1.0)
        .view_aspect(1.0)
        .show_axes(false)
        .show_grid(false)
        .allow_drag(false)
        .allow_zoom(false)
        .allow_scroll(false)
        .include_x(-1.3)
        .include_x(1.3)
        .include_y(-1.3)
        .include_y(1.3)
        .legend(Legend::default())
        .show(ui, |p| {
            let ring: Vec<[f64; 2]> = (0..=96)
                .map(|k| rose_point(period * k as f64 / 96.0, 1.0, period))
                .collect();
            p.line(Line::new("", PlotPoints::from(ring)).color(Color32::GRAY));
            for wedge in rose_wedges(&errors, period) {
                p.polygon(
                    egui_plot::Polygon::new("", PlotPoints::from(wedge))
                        .fill_color(KDE_COLOUR.gamma_multiply(0.6))
                        .stroke(egui::Stroke::new(1.0, KDE_COLOUR)),
                );
            }
            for (deg, text) in [
                (0.0, "0°".to_string()),
                (half / 2.0, format!("+{}°", half / 2.0)),
                (half, format!("±{half}°")),
                (-half / 2.0, format!("−{}°", half / 2.0)),
            ] {
                let [x, y] = rose_point(deg, 1.18, period);
                p.text(egui_plot::Text::new("", [x, y].into(), text));
            }
            let rays = [
                (
                    rep.estimate.as_ref(),
                    ESTIMATE_COLOUR,
                    "single-sample estimate",
                ),
                (
                    rep.multi_sample.as_ref(),
                    MULTI_COLOUR,
                    "multi-sample estimate",
                ),
                (rep.baseline.as_ref(), BASELINE_COLOUR, "baseline"),
            ];
            for (e, colour, name) in rays {
                if let Some(v) = e.and_then(|e| e.theta_deg) {
                    let tip = rose_point(v, 1.05, period);
                    p.line(
                        Line::new(name, PlotPoints::from(vec![[0.0, 0.0], tip]))
                            .color(colour)
                            .width(2.0),
                    );
                }
            }
        });
    let name = format!("θ error circular histogram, {} samples", errors.len());
    response
        .response
        .widget_info(|| egui::WidgetInfo::labeled(egui::accesskit::Role::Figure, true, &name));
}

#[cfg(test)]
mod tests {
    use super::{step_label, steps_1_2_10};

    #[test]
    fn tick_labels_carry_the_decimals_of_their_step() {
        let label = |value: f64, step_size: f64| {
            step_label(egui_plot::GridMark { value, step_size }, &(0.0..=1.0))
        };
        assert_eq!(label(1.5, 0.5), "1.5");
        assert_eq!(label(0.5, 0.5), "0.5");
        assert_eq!(label(0.4, 0.2), "0.4");
        assert_eq!(label(2.0, 1.0), "2");
        assert_eq!(label(20.0, 10.0), "20");
        assert_eq!(label(0.05, 0.05), "0.05");
        assert_eq!(label(-0.1, 0.1), "-0.1");
    }

    #[test]
    fn grid_steps_follow_1_2_5_and_divide_each_other() {
        let steps = |base: f64| {
            steps_1_2_10(egui_plot::GridInput {
                bounds: (-1.0, 4.0),
                base_step_size: base,
            })
        };
        let close =
            |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9 * y);
        assert!(close(steps(0.15), [0.2, 1.0, 2.0]), "{:?}", steps(0.15));
        assert!(close(steps(0.7), [1.0, 2.0, 10.0]), "{:?}", steps(0.7));
        assert!(close(steps(3.0), [5.0, 10.0, 50.0]), "{:?}", steps(3.0));
        assert!(close(steps(1.0), [1.0, 2.0, 10.0]), "{:?}", steps(1.0));
        for k in -40..40 {
            let base = 1.37f64.powi(k);
            let s = steps(base);
            assert!(s[0] >= base * (1.0 - 1e-12), "{base}: {s:?}");
            for w in s.windows(2) {
                let ratio = w[1] / w[0];
                assert!(
                    (ratio - ratio.round()).abs() < 1e-9 && ratio >= 2.0 - 1e-9,
                    "{base}: {s:?}"
                );
            }
        }
    }
}
