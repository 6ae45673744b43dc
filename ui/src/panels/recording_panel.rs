//! Recording tab: a real sensor recording (MCAP file or depth-frame folder) on a timeline. Scrub the frames, see the
//! imprint, signature and reference of the frame under the cursor, the contact area over time, and de-render (and
//! register) the frame under the cursor.

use egui_plot::{Line, Plot, PlotPoints, Points, VLine};
use tactile_derender::pipeline::track::FrameTrack;
use tactile_derender::recording::{ProcessedRecording, ReferenceChoice, StreamKind};

use super::image_card::{self, Scale};
use super::widgets::path_submit;
use crate::app::{PathInputs, WorkbenchApp};
use crate::command::Command;
use crate::recording_view::{LoadedRecording, RecordingSettings, RecordingView, IMPRINT_RANGE};
use crate::sensor_calibration::SensorCalibrationView;
use crate::worker::DialogPurpose;

/// The Recording tab; `inputs.recording_path` is the typed recording. Takes `&mut WorkbenchApp` because the frame's
/// and the sensor calibration's textures are made lazily, when first drawn.
pub fn show(
    app: &mut WorkbenchApp,
    inputs: &mut PathInputs,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    open_row(&mut inputs.recording_path, ui, cmds);
    if app.recording.loading {
        ui.horizontal(|ui| {
            if progress_row(
                ui,
                "reading frames",
                "",
                app.recording.progress,
                "Cancel reading",
            ) {
                cmds.push(Command::CancelRecording);
            }
        });
    }
    let Some(loaded) = &app.recording.loaded else {
        if !app.recording.loading {
            ui.label(
                "Open a sensor recording: an MCAP file (a ROS 2 bag with sensor_msgs/Image depth in 16UC1 mm or 32FC1 \
                 m, or PointCloud2) or a folder of depth frames (16-bit PNG in mm, .npy in metres). Each frame becomes \
                 an imprint Y = R − S at the model resolution, cropped and resampled as the simulator does. Try one \
                 made by `tnd recording simulate press.mcap --object cylinder_r12`.",
            );
        }
        return;
    };
    let p = loaded.processed.clone();
    let n = p.len();
    let mut s = app.state.recording.clone();
    read_settings_row(ui, loaded, &mut s);
    summary(ui, loaded, app.state.sim.camera.resolution);
    let times = p.times_s();
    timeline_row(ui, &mut s, n);
    let k = s.frame.min(n.saturating_sub(1));
    frame_line(ui, loaded, &times, k);
    derender_buttons(ui, cmds);
    calibration_section(&mut app.recording.sensor_calibration, ui, cmds);
    if let Some(frame) = track_section(app, ui, cmds, &times) {
        s.frame = frame;
    }
    if let Some(frame) = contact_plot(ui, &p, &times, k) {
        s.frame = frame;
    }
    frame_images(ui, &mut app.recording, &p, k);
    if s != app.state.recording {
        cmds.push(Command::SetRecording(s));
    }
}

/// The reading settings in one row: the depth topic, the reference (auto or the frame under the cursor) and the
/// contact threshold, edited in `s`.
fn read_settings_row(ui: &mut egui::Ui, loaded: &LoadedRecording, s: &mut RecordingSettings) {
    ui.horizontal(|ui| {
        let depth: Vec<&str> = loaded
            .streams
            .iter()
            .filter(|t| matches!(t.kind, StreamKind::DepthImage | StreamKind::PointCloud))
            .map(|t| t.name.as_str())
            .collect();
        ui.label("depth topic");
        egui::ComboBox::from_id_salt("rec_topic")
            .selected_text(loaded.processed.stream.as_str())
            .show_ui(ui, |ui| {
                for t in depth {
                    ui.selectable_value(&mut s.read.topic, Some(t.to_string()), t);
                }
            })
            .response
            .on_hover_text("the depth stream of the recording (sensor_msgs/Image or PointCloud2)");
        ui.label("reference");
        let auto = s.read.reference == ReferenceChoice::Auto;
        if ui
            .radio(auto, "auto")
            .on_hover_text(
                "the median of the frames without contact (5 x 5-averaged imprint under 1 mm against the deepest frame)",
            )
            .clicked()
        {
            s.read.reference = ReferenceChoice::Auto;
        }
        if ui
            .button("Use this frame as the reference")
            .on_hover_text("take the frame under the cursor as the no-contact reference R")
            .clicked()
        {
            s.read.reference = ReferenceChoice::Frame(s.frame);
        }
        if let ReferenceChoice::Frame(k) = s.read.reference {
            ui.label(format!("frame {k}"));
        }
        // The contact threshold in mm on screen, metres in the settings (`--contact-threshold` of the CLI).
        let mut threshold_mm = s.read.contact_threshold_m * 1e3;
        ui.label("contact threshold");
        if ui
            .add(
                egui::DragValue::new(&mut threshold_mm)
                    .range(0.1..=20.0)
                    .speed(0.05)
                    .suffix(" mm"),
            )
            .on_hover_text(
                "imprint above which a pixel counts as contact (the frames tracked and their contact area; \
                 tnd recording track --contact-threshold)",
            )
            .changed()
        {
            s.read.contact_threshold_m = threshold_mm * 1e-3;
        }
    });
}

/// What was read (frames, sizes, reference frames, object pose) and a warning when the membrane drifted;
/// `resolution` is the model's (the simulator camera's).
fn summary(ui: &mut egui::Ui, loaded: &LoadedRecording, resolution: (usize, usize)) {
    let p = &loaded.processed;
    let has_pose = loaded.poses.iter().any(Option::is_some);
    ui.weak(format!(
        "{} frames of {}x{}, resampled to {}x{}; reference from frame(s) {}; object pose: {}",
        p.len(),
        p.source_size[0],
        p.source_size[1],
        resolution.0,
        resolution.1,
        short_list(&p.reference_frames),
        if has_pose {
            "from the recording's pose topic"
        } else {
            "none recorded (registering finds the press from the samples)"
        }
    ));
    if p.drift_m() > tactile_derender::recording::drift::DRIFT_TOLERANCE_M {
        ui.colored_label(
            ui.visuals().warn_fg_color,
            format!(
                "the membrane drifted up to {:.2} mm between no-contact stretches: each frame's imprint is taken \
                 against the references before and after it, blended by its time",
                p.drift_m() * 1e3
            ),
        );
    }
}

/// The timeline: previous, a slider over the `n` frames and next, moving `s.frame`.
fn timeline_row(ui: &mut egui::Ui, s: &mut RecordingSettings, n: usize) {
    ui.horizontal(|ui| {
        if ui
            .button("< previous")
            .on_hover_text("previous frame")
            .clicked()
        {
            s.frame = s.frame.saturating_sub(1);
        }
        let width = (ui.available_width() - 260.0).max(120.0);
        ui.spacing_mut().slider_width = width;
        ui.add(egui::Slider::new(&mut s.frame, 0..=n.saturating_sub(1)).text("frame"))
            .on_hover_text("scrub the recording; the images and the cursor follow");
        if ui.button("next >").on_hover_text("next frame").clicked() {
            s.frame = (s.frame + 1).min(n.saturating_sub(1));
        }
    });
}

/// One line on frame `k`: its time, contact, pixels without a return and the recorded object pose.
fn frame_line(ui: &mut egui::Ui, loaded: &LoadedRecording, times: &[f64], k: usize) {
    let p = &loaded.processed;
    let n = p.len();
    let seen = p.reference_for(k).count_nonzero();
    let missing = seen.saturating_sub(p.measured_px.get(k).copied().unwrap_or(0));
    ui.label(format!(
        "frame {k} of {n}, t = {:.3} s, contact {} px (imprint > 3 mm), {missing} px without a return{}",
        times.get(k).copied().unwrap_or(0.0),
        p.contact_px.get(k).copied().unwrap_or(0),
        loaded
            .poses
            .get(k)
            .copied()
            .flatten()
            .map_or(String::new(), |q| format!(
                ", object at x {:.1} mm, y {:.1} mm, θ {:.1}°",
                q.x * 1e3,
                q.y * 1e3,
                q.theta.to_degrees()
            ))
    ));
}

/// The two buttons that de-render (and register) the frame under the cursor.
fn derender_buttons(ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        if ui
            .button("De-render this frame")
            .on_hover_text(
                "sample the in-contact depth of this frame's imprint (De-render tab settings)",
            )
            .clicked()
        {
            cmds.push(Command::DerenderFrame { pose: false });
        }
        if ui
            .button("De-render and register this frame")
            .on_hover_text(
                "sample, then register the samples to the Scene panel's object (Pose tab)",
            )
            .clicked()
        {
            cmds.push(Command::DerenderFrame { pose: true });
        }
    });
}

/// The contact area over time with the cursor at frame `k`; a click answers the frame nearest in time.
fn contact_plot(
    ui: &mut egui::Ui,
    p: &ProcessedRecording,
    times: &[f64],
    k: usize,
) -> Option<usize> {
    let area: Vec<[f64; 2]> = times
        .iter()
        .zip(&p.contact_px)
        .map(|(&t, &c)| [t, c as f64])
        .collect();
    let cursor = times.get(k).copied().unwrap_or(0.0);
    let plot = Plot::new("rec_contact")
        .height(140.0)
        .x_axis_label("time (s)")
        .y_axis_label("contact (px)")
        .allow_drag(false)
        .show(ui, |pl| {
            pl.line(Line::new("contact area", PlotPoints::from(area)));
            pl.vline(VLine::new("frame", cursor));
            pl.pointer_coordinate()
        });
    if !plot.response.clicked() {
        return None;
    }
    let at = plot.inner?;
    (0..p.len()).min_by(|&a, &b| (times[a] - at.x).abs().total_cmp(&(times[b] - at.x).abs()))
}

/// Frame `k`'s imprint, signature and reference side by side.
fn frame_images(ui: &mut egui::Ui, view: &mut RecordingView, p: &ProcessedRecording, k: usize) {
    let side = ((ui.available_width() - 3.0 * 90.0) / 3.0).clamp(96.0, 420.0);
    let ctx = ui.ctx().clone();
    let Some(tex) = view.textures_for(&ctx, k) else {
        return;
    };
    let depth = tex.depth_range;
    ui.horizontal(|ui| {
        let imprint = Scale {
            range: IMPRINT_RANGE,
            millimetres: true,
            zero_is_missing: false,
        };
        let depth_scale = Scale {
            range: depth,
            millimetres: true,
            zero_is_missing: true,
        };
        image_card::card(
            ui,
            "imprint Y = R - S",
            tex.imprint.id(),
            &p.imprints[k],
            &imprint,
            side,
        );
        image_card::card(
            ui,
            "signature S",
            tex.signature.id(),
            &p.signatures[k],
            &depth_scale,
            side,
        );
        image_card::card(
            ui,
            "reference R",
            tex.reference.id(),
            &p.reference,
            &depth_scale,
            side,
        );
    });
}

/// The track's own settings beside its button: every n-th frame, and whether each frame carries the previous one's
/// estimate forward (`tnd recording track --every` and `--per-frame`).
fn track_settings(app: &WorkbenchApp, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    let mut s = app.state.recording.clone();
    ui.label("every");
    ui.add(
        egui::DragValue::new(&mut s.track.every)
            .range(1..=1000)
            .suffix(" frame(s)"),
    )
    .on_hover_text("track every n-th frame (tnd recording track --every)");
    let mut carry = !s.track.tracking.per_frame;
    if ui
        .checkbox(&mut carry, "carry estimates forward")
        .on_hover_text(
            "each frame starts from the previous frame's estimate with fewer samples and its posterior as the prior \
             (off: every frame from scratch, as tnd recording track --per-frame)",
        )
        .changed()
    {
        s.track.tracking.per_frame = !carry;
    }
    if s != app.state.recording {
        cmds.push(Command::SetRecording(s));
    }
}

fn open_row(recording_path: &mut String, ui: &mut egui::Ui, cmds: &mut Vec<Command>) {
    ui.horizontal(|ui| {
        if let Some(path) = path_submit(
            ui,
            "recording",
            recording_path,
            ".mcap file or frame folder",
            "Open recording",
        ) {
            cmds.push(Command::OpenRecording(path.into()));
        }
        if ui
            .button("Browse MCAP…")
            .on_hover_text("a ROS 2 bag (.mcap); dropping it on the window opens it too")
            .clicked()
        {
            cmds.push(Command::Browse(DialogPurpose::OpenRecording));
        }
        if ui
            .button("Browse frame folder…")
            .on_hover_text(
                "a folder of depth frames: 16-bit PNG in mm or .npy in metres, in name order",
            )
            .clicked()
        {
            cmds.push(Command::Browse(DialogPurpose::OpenRecordingFolder));
        }
    });
}

/// "`what`… done/total`unit`", a progress bar and a cancel button (true when it was clicked), in the current row.
fn progress_row(
    ui: &mut egui::Ui,
    what: &str,
    unit: &str,
    progress: Option<(usize, usize)>,
    cancel: &str,
) -> bool {
    let (done, total) = progress.unwrap_or((0, 0));
    ui.label(format!("{what}… {done}/{total}{unit}"));
    ui.add(
        egui::ProgressBar::new(if total > 0 {
            done as f32 / total as f32
        } else {
            0.0
        })
        .desired_width(200.0),
    );
    ui.button(cancel).clicked()
}

/// The sensor calibration: one button, its progress, and the fit (what changed, the residual, three images).
fn calibration_section(
    view: &mut SensorCalibrationView,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
) {
    ui.horizontal(|ui| {
        if view.running {
            if progress_row(ui, "calibrating", " frames", view.progress, "Cancel calibration") {
                cmds.push(Command::CancelSensorCalibration);
            }
        } else if ui
            .button("Calibrate sensor from this recording")
            .on_hover_text(
                "fit the membrane (inflation; footprint with tnd calibrate --fit-footprint), the camera position and the depth \
                 noise to the frames without contact, and use the calibrated sensor in every tab (Undo restores the \
                 previous one); `tnd calibrate --from` does the same",
            )
            .clicked()
        {
            cmds.push(Command::CalibrateSensor);
        }
    });
    let ctx = ui.ctx().clone();
    let Some(result) = &view.result else {
        return;
    };
    let lines = result.calibration.summary_lines();
    let (measured, fitted, residual) = (
        result.images.measured.clone(),
        result.images.fitted.clone(),
        result.images.residual.clone(),
    );
    egui::CollapsingHeader::new("sensor calibration")
        .default_open(true)
        .show(ui, |ui| {
            for line in &lines {
                if line.starts_with("warning:") {
                    ui.colored_label(ui.visuals().warn_fg_color, line);
                } else {
                    ui.label(line);
                }
            }
            if ui
                .button("Save sensor file")
                .on_hover_text(
                    "write the calibrated sensor beside the recording (<recording>_sensor.json): tnd --sensor FILE, \
                     tnd-workbench --sensor FILE",
                )
                .clicked()
            {
                cmds.push(Command::SaveSensorFile);
            }
            let Some(tex) = view.textures(&ctx) else {
                return;
            };
            let side = ((ui.available_width() - 3.0 * 90.0) / 3.0).clamp(96.0, 320.0);
            let depth = Scale {
                range: tex.depth_range,
                millimetres: true,
                zero_is_missing: true,
            };
            let res = Scale {
                range: tex.residual_range,
                millimetres: true,
                zero_is_missing: false,
            };
            ui.horizontal(|ui| {
                image_card::card(
                    ui,
                    "measured reference",
                    tex.measured.id(),
                    &measured,
                    &depth,
                    side,
                );
                image_card::card(
                    ui,
                    "calibrated membrane",
                    tex.fitted.id(),
                    &fitted,
                    &depth,
                    side,
                );
                image_card::card(
                    ui,
                    "measured - calibrated",
                    tex.residual.id(),
                    &residual,
                    &res,
                    side,
                );
            });
        });
}

/// "0-7, 21-26, 28" for a sorted list of frames.
fn short_list(frames: &[usize]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    while i < frames.len() {
        let mut j = i;
        while j + 1 < frames.len() && frames[j + 1] == frames[j] + 1 {
            j += 1;
        }
        parts.push(if j > i {
            format!("{}-{}", frames[i], frames[j])
        } else {
            frames[i].to_string()
        });
        i = j + 1;
    }
    parts.join(", ")
}

/// The track: start / cancel / save, its progress, and the pose over time (a click moves the cursor there).
fn track_section(
    app: &WorkbenchApp,
    ui: &mut egui::Ui,
    cmds: &mut Vec<Command>,
    times: &[f64],
) -> Option<usize> {
    let t = &app.recording.track;
    ui.horizontal(|ui| {
        if t.running {
            if progress_row(ui, "tracking", " frames", t.progress, "Cancel tracking") {
                cmds.push(Command::CancelTrack);
            }
        } else if ui
            .button("Track all frames")
            .on_hover_text(
                "de-render and register every frame with contact (the De-render tab's model, samples and sampler; \
                 the Scene panel's object; the press found per frame), as `tnd recording track` does",
            )
            .clicked()
        {
            cmds.push(Command::TrackRecording);
        }
        if !t.running {
            track_settings(app, ui, cmds);
        }
        if !t.rows.is_empty()
            && !t.running
            && ui
                .button("Save track CSV")
                .on_hover_text("write the rows as <recording>_track.csv beside the recording")
                .clicked()
        {
            cmds.push(Command::SaveTrack);
        }
    });
    let same = t.recording.as_ref() == app.recording.loaded.as_ref().map(|l| &l.path);
    if t.rows.is_empty() || !same {
        return None;
    }
    let at = |frame: usize| times.get(frame).copied().unwrap_or(0.0);
    let series = |get: fn(&FrameTrack) -> Option<f64>| -> Vec<[f64; 2]> {
        t.rows
            .iter()
            .filter_map(|r| get(r).map(|v| [at(r.frame), v]))
            .collect()
    };
    let scored = t.rows.iter().any(|r| r.recorded.is_some());
    let errors: Vec<f64> = t
        .rows
        .iter()
        .filter_map(|r| r.estimate_error.map(|e| e.0))
        .collect();
    // Each row's ±σ read as a Gaussian's: the central intervals holding 68 % of its estimate's mode.
    let half: Vec<Option<[f64; 3]>> = t.rows.iter().map(|r| r.half_width_68).collect();
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    let spread = match (
        median(
            half.iter()
                .flatten()
                .map(|h| h[0].hypot(h[1]) * 1e3 / 2f64.sqrt())
                .collect(),
        ),
        median(half.iter().flatten().map(|h| h[2].to_degrees()).collect()),
    ) {
        (Some(p), Some(th)) => format!("; median 68 % interval ±{p:.2} mm, ±{th:.1}°"),
        _ => String::new(),
    };
    ui.label(if errors.is_empty() {
        format!("track: {} frames{spread}", t.rows.len())
    } else {
        let theta: Vec<f64> = t
            .rows
            .iter()
            .filter_map(|r| r.estimate_error.and_then(|e| e.1).map(f64::abs))
            .collect();
        format!(
            "track: {} frames; position error against the recorded pose {:.2} mm mean{}{spread}",
            t.rows.len(),
            errors.iter().sum::<f64>() / errors.len() as f64,
            median(theta)
                .map(|m| format!(", θ {m:.1}° median"))
                .unwrap_or_default()
        )
    });
    let width = (ui.available_width() / 2.0 - 8.0).max(200.0);
    let mut clicked = None;
    ui.horizontal(|ui| {
        let position = Plot::new("rec_track_xy")
            .height(160.0)
            .width(width)
            .legend(egui_plot::Legend::default())
            .x_axis_label("time (s)")
            .y_axis_label("position (mm)")
            .allow_drag(false)
            .show(ui, |pl| {
                let x = series(|r| r.estimate.map(|p| p.x * 1e3));
                let y = series(|r| r.estimate.map(|p| p.y * 1e3));
                pl.points(Points::new("x estimate", x).radius(2.5));
                pl.points(Points::new("y estimate", y).radius(2.5));
                if scored {
                    let x = series(|r| r.recorded.map(|p| p.x * 1e3));
                    let y = series(|r| r.recorded.map(|p| p.y * 1e3));
                    pl.line(Line::new("x recorded", PlotPoints::from(x)));
                    pl.line(Line::new("y recorded", PlotPoints::from(y)));
                }
                pl.pointer_coordinate()
            });
        // θ against the recorded pose where there is one (the error knows the object's symmetry), else θ itself.
        let (label, theta): (&str, Vec<[f64; 2]>) = if scored {
            (
                "θ error (°)",
                series(|r| r.estimate_error.and_then(|e| e.1)),
            )
        } else {
            (
                "θ (°)",
                series(|r| {
                    r.estimate.map(|p| {
                        let pi = std::f64::consts::PI;
                        ((p.theta + pi).rem_euclid(2.0 * pi) - pi).to_degrees()
                    })
                }),
            )
        };
        let angle = Plot::new("rec_track_theta")
            .height(160.0)
            .width(width)
            .x_axis_label("time (s)")
            .y_axis_label(label)
            .allow_drag(false)
            .legend(egui_plot::Legend::default())
            .show(ui, |pl| {
                pl.points(Points::new("θ", theta).radius(2.5));
                if scored {
                    // σ beside the error: the estimate's ±68 % θ interval about 0.
                    for sign in [1.0, -1.0] {
                        let band: Vec<[f64; 2]> = t
                            .rows
                            .iter()
                            .zip(&half)
                            .filter_map(|(r, h)| h.map(|h| [at(r.frame), sign * h[2].to_degrees()]))
                            .collect();
                        pl.line(Line::new("±68 % interval", PlotPoints::from(band)));
                    }
                }
                pl.pointer_coordinate()
            });
        for p in [position, angle] {
            if let (true, Some(pointer)) = (p.response.clicked(), p.inner) {
                clicked = t
                    .rows
                    .iter()
                    .min_by(|a, b| {
                        (at(a.frame) - pointer.x)
                            .abs()
                            .total_cmp(&(at(b.frame) - pointer.x).abs())
                    })
                    .map(|r| r.frame);
            }
        }
    });
    clicked
}
