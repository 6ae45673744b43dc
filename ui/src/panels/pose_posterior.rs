//! The Pose tab's posterior line ([`tactile_derender::pose::posterior`]): its modes, the share that the pose is none
//! of them, σ about the estimate (and the central intervals holding 68 %) and, with a truth, the estimate's error
//! beside it and the smallest region holding it.

use crate::pose_view::PoseAnalysis;

/// The posterior in one line: its modes, the share that the pose is none of them, the estimate's σ (the covariance
/// about it, other modes included) and, with a truth, the estimate's error beside it and the smallest region holding
/// the truth.
pub fn posterior_summary(ui: &mut egui::Ui, r: &PoseAnalysis) {
    let (Some(post), Some(est)) = (&r.posterior, r.single_estimate()) else {
        return;
    };
    let Some(cov) = tactile_derender::pose::export::covariance_about(post, est, &r.symmetry) else {
        return;
    };
    let top = post.modes.first().map_or(0.0, |m| m.weight);
    let far = post.modes.first().map_or(0.0, |m| m.tails.far);
    let theta_free = r.symmetry.rotation.period_rad().is_none();
    // The estimate's mode's central intervals holding 68 %: its spread read as a Gaussian's ±σ (heavy tails make
    // the standard deviation far wider than the typical error).
    let half = post.estimate_half_widths(est, &r.symmetry);
    let theta_sigma = if theta_free {
        "θ free".to_string()
    } else {
        format!("θ {:.1}°", cov[2][2].sqrt().to_degrees())
    };
    let within = half
        .map(|h| {
            let theta = if theta_free {
                String::new()
            } else {
                format!(", ±{:.1}°", h[2].to_degrees())
            };
            format!(
                " (68 % within ±{:.2} mm, ±{:.2} mm{theta})",
                h[0] * 1e3,
                h[1] * 1e3
            )
        })
        .unwrap_or_default();
    let truth = r
        .truth
        .map(|t| {
            let no_axis = tactile_derender::objects::Symmetry {
                translation_axis: None,
                ..r.symmetry
            };
            let (e, _) = tactile_derender::pose::posterior::reduced_difference(est, t, &no_axis);
            let theta = e
                .get(2)
                .map(|v| format!(", θ {:.1}°", v.abs().to_degrees()))
                .unwrap_or_default();
            let region = r
                .truth_region
                .map(|m| {
                    format!(
                        " — the truth is inside its {:.0} % region and every wider one",
                        (m * 100.0).ceil().clamp(1.0, 100.0)
                    )
                })
                .unwrap_or_default();
            format!(
                "; error x {:.2} mm, y {:.2} mm{theta}{region}",
                e[0].abs() * 1e3,
                e[1].abs() * 1e3
            )
        })
        .unwrap_or_default();
    let text = format!(
        "posterior: {} mode{} (top weight {:.2}; {:.0} % that it is none of them); σ x {:.2} mm, y {:.2} mm, \
         {theta_sigma}{within}{truth}",
        post.modes.len(),
        if post.modes.len() == 1 { "" } else { "s" },
        top,
        far * 100.0,
        cov[0][0].sqrt() * 1e3,
        cov[1][1].sqrt() * 1e3,
    );
    let label = if top < 0.7 {
        ui.colored_label(ui.visuals().warn_fg_color, text)
    } else {
        ui.label(text)
    };
    let noise = post
        .noise
        .map(|n| {
            format!(
                " This frame's noise about the best mode: {:.2} mm (the sensor model assumes {:.2} mm a pixel).{}",
                n.measured_m * 1e3,
                n.assumed_m * 1e3,
                n.contact_rms_m
                    .map(|c| format!(
                        " On the contact the best mode leaves {:.2} mm unexplained ({:.1}x the frame's noise; \
                         the more, the heavier the tails).",
                        c * 1e3,
                        n.ln_misfit().exp()
                    ))
                    .unwrap_or_default()
            )
        })
        .unwrap_or_default();
    label.on_hover_text(format!(
        "What the measured signature supports: each pose the signature check refined is a mode, weighted by how well \
         it explains the signature (tempered for correlated pixels), with a sharp core from the curvature of that \
         fit, a wider tail for a contact the sample got somewhat wrong and a far share for a pose no hypothesis came \
         near; the shares grow on small contacts, with rival poses that explain the signature nearly as well, and where \
         the best pose leaves the contact unexplained. Fitted to validation data by the log density of the truth \
         (docs/uncertainty.md). σ is about the estimate, other modes' cores and tails included — what pose.json's \
         pose_with_covariance carries.{noise}",
    ));
}
