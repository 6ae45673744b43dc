//! The **pose posterior's calibration** ([`PosteriorConfig`]): how the signature check's likelihood becomes a
//! calibrated posterior ([`super::posterior`]) — temperatures, floors and heavy tails, with their units, defaults
//! (fitted on validation data) and bounds.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::InvalidInput;

/// How the check's likelihood becomes a calibrated posterior ([`super::posterior`] module docs). The defaults were fitted
/// (`tnd posterior --fit`) to the bundled model's records on the real validation meshes (`docs/uncertainty.md`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PosteriorConfig {
    /// τ of the modes' weights: the log-likelihood is divided by this (1 trusts every pixel as independent).
    pub temperature: f64,
    /// τ_c of the modes' core covariances τ_c·H⁻¹.
    pub covariance_temperature: f64,
    /// Standard deviation added to every mode's x and y, metres.
    pub floor_position_m: f64,
    /// Standard deviation added to every mode's θ, radians.
    pub floor_theta_rad: f64,
    /// The floors hold for a contact of this many pixels (the signature's pixels in front of the membrane by more
    /// than `contact_threshold_m`); they scale by (this / contact pixels)^`floor_exponent`, so that a small contact,
    /// which says less about the pose, gets wider regions.
    pub floor_contact_px: f64,
    /// See `floor_contact_px` (0: the same floors for every contact).
    pub floor_exponent: f64,
    /// Depth in front of the membrane that counts as contact for `floor_contact_px`, metres (the threshold
    /// baseline's 3 mm).
    pub contact_threshold_m: f64,
    /// Scale the floors and tails by the contact the best mode predicts instead of the one counted on the measured
    /// signature (which the sensor's noise inflates); falls back to the measured count where no prediction was kept.
    pub contact_from_prediction: bool,
    /// Weigh the check's evidence by the frame's own noise ([`super::posterior::FrameNoise`]): nats and Hessians
    /// times σ₀² / (σ_f² + `noise_floor_m`²), σ₀ the noise they were computed with, σ_f the frame's; off, or where a
    /// record has no measured noise, σ_f = σ₀. Absent from a calibration file: off (its numbers were fitted to the
    /// evidence as recorded, before this setting existed; `tnd posterior --fit` writes it).
    #[serde(default = "calibrated_without_frame_noise")]
    pub frame_noise: bool,
    /// Standard deviation added in quadrature to the frame's noise (what the model and the membrane get wrong, which
    /// no averaging removes), metres.
    pub noise_floor_m: f64,
    /// Modes lighter than this are left out (and the rest renormalised).
    pub min_weight: f64,
    /// Most modes kept (the lowest Δ first); each costs a Hessian (18 predicted signatures).
    pub max_modes: usize,
    /// Central-difference step of the Hessian, metres (θ: this over `lever_m`).
    pub step_m: f64,
    /// Lever arm converting rotation to length for the Hessian's step and its caps, metres.
    pub lever_m: f64,
    /// Largest standard deviation along any direction the signature leaves flat (rotation as arc at `lever_m`),
    /// metres.
    pub max_sigma_m: f64,
    /// Logit of the tail's share of a mode at a contact of `floor_contact_px` pixels (module docs).
    pub tail_logit: f64,
    /// Change of that logit per unit of ln(contact pixels / `floor_contact_px`) (negative: small contacts have more).
    pub tail_contact_slope: f64,
    /// Standard deviation the tail adds to the core's x and y, metres.
    pub tail_position_m: f64,
    /// Standard deviation the tail adds to the core's θ, radians.
    pub tail_theta_rad: f64,
    /// The tail's added spreads hold for a contact of `floor_contact_px` pixels and scale by (that / contact
    /// pixels)^this, as the floors do.
    pub tail_exponent: f64,
    /// The tail's covariance is the core's times this squared, plus the added spreads.
    pub tail_core_scale: f64,
    /// Logit of the far component's share of a mode at a contact of `floor_contact_px` pixels.
    pub far_logit: f64,
    /// Change of that logit per unit of ln(contact pixels / `floor_contact_px`).
    pub far_contact_slope: f64,
    /// Standard deviation of the far component's x and y about the mode, metres (its θ is uniform), at a contact of
    /// `floor_contact_px` pixels; it scales by (that / contact pixels)^`far_exponent`.
    pub far_position_m: f64,
    /// See `far_position_m`.
    pub far_exponent: f64,
    /// Change of the far logit per unit of the modes' disagreement, 1 − the top mode's weight (the hypotheses
    /// split between poses: more often none of them is right).
    pub far_ambiguity: f64,
    /// A rival explanation is a distinct pose the check refined to within this many nats of the best (as computed,
    /// at the sensor model's noise, whatever [`Self::frame_noise`] weighs them by): the number of them, n (the best
    /// included), says how rough the likelihood is around this contact — one pose that explains the signature and
    /// no other is a contact the core describes. Records keep every distinct pose's nats, so a refit can change it.
    pub rival_window_nats: f64,
    /// Change of the tail's logit per unit of ln n ([`Self::rival_window_nats`]). Absent from a calibration file: 0
    /// (fitted before it existed).
    #[serde(default)]
    pub tail_rivals: f64,
    /// Change of the far component's logit per unit of ln n. Absent from a calibration file: 0.
    #[serde(default)]
    pub far_rivals: f64,
    /// Change of the tail's logit per unit of ln(the contact's misfit / the frame's noise)
    /// ([`super::posterior::FrameNoise::ln_misfit`]): a pose that leaves the contact unexplained is more often
    /// somewhat wrong. Absent from a calibration file: 0.
    #[serde(default)]
    pub tail_misfit: f64,
    /// The same for the far component's logit. Absent from a calibration file: 0.
    #[serde(default)]
    pub far_misfit: f64,
    /// κ, how much a track's previous frame counts as the prior of the next ([`super::fusion`]), 0–1: the previous
    /// posterior's prediction of each mode is raised to this power (a power prior; the frame two back then counts
    /// κ², as the fusion passes on). Neighbouring frames of one press share the model's and the membrane's errors,
    /// so their evidence is worth less than independent frames' would be; 1 treats it as independent, 0 leaves
    /// every frame its own. Absent from a calibration file: 1 (how tracks were fused before it existed).
    #[serde(default = "independent_frames")]
    pub fusion_weight: f64,
    /// The calibration for frames brought to the model's resolution from the camera's native pixels and checked
    /// there ([`super::camera_path`]: recordings, imported pairs, native `.npy` frames), whose evidence the native
    /// prediction makes sharper than the same check's on frames made at the model's resolution. Absent (a
    /// calibration file, `tnd posterior --fit`'s included): this calibration for every frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resampled_frames: Option<Box<PosteriorConfig>>,
}

/// [`PosteriorConfig::fusion_weight`] of a calibration written before it existed.
fn independent_frames() -> f64 {
    1.0
}

/// [`PosteriorConfig::frame_noise`] of a calibration written before it existed.
fn calibrated_without_frame_noise() -> bool {
    false
}

impl Default for PosteriorConfig {
    /// For frames made at the model's resolution: fitted (`tnd posterior --fit`, rounded to three digits) to 529
    /// pairs of the bundled model's records on the 42 real validation meshes — nominal single frames, press
    /// recordings with and without a time-of-flight camera's artefacts, three off-nominal sensors, all checked one
    /// ray per model pixel — and to 338 frames of 41 tracked presses of the same meshes (the fusion of each carried
    /// frame replayed; since session 36; docs/uncertainty.md, where the same fit held out by object is scored). The
    /// fit chose the predicted contact and the evidence as recorded; the tails also follow the rival explanations
    /// (within 50 nats) and the contact's misfit. The fusion weight (since session 37) was fitted to the tracks with
    /// the rest as it was: the previous frame's prediction counts at the power 0.15. Frames resampled from the
    /// camera's native pixels: [`Self::resampled_frames_bundled`].
    fn default() -> Self {
        Self {
            resampled_frames: Some(Box::new(Self::resampled_frames_bundled())),
            ..Self::model_resolution_bundled()
        }
    }
}

impl PosteriorConfig {
    /// [`Self::default`] without its calibration for resampled frames.
    fn model_resolution_bundled() -> Self {
        Self {
            temperature: 1.69,
            covariance_temperature: 1.8,
            floor_position_m: 2.57e-5,
            floor_theta_rad: 0.00437,
            floor_contact_px: 300.0,
            floor_exponent: 0.996,
            contact_threshold_m: 0.003,
            contact_from_prediction: true,
            frame_noise: false,
            noise_floor_m: 7.05e-4,
            min_weight: 1e-3,
            max_modes: 10,
            step_m: 5e-4,
            lever_m: 0.02,
            max_sigma_m: 0.03,
            tail_logit: -1.96,
            tail_contact_slope: -0.0277,
            tail_position_m: 0.000279,
            tail_theta_rad: 0.0823,
            tail_exponent: 0.435,
            tail_core_scale: 3.19,
            far_logit: -6.21,
            far_contact_slope: 0.559,
            far_position_m: 0.00395,
            far_exponent: 0.455,
            far_ambiguity: -1.67,
            rival_window_nats: 50.0,
            tail_rivals: 0.902,
            far_rivals: 2.33,
            tail_misfit: 6.43,
            far_misfit: 4.84,
            fusion_weight: 0.15,
            resampled_frames: None,
        }
    }

    /// The bundled calibration of [`Self::resampled_frames`]: fitted (`tnd posterior --fit`, rounded to three digits)
    /// to the recording model's records (`--model auto`'s pick) of imported recordings on the 42 real validation
    /// meshes — clean and with a time-of-flight camera's artefacts, every frame, and three off-nominal sensors (579
    /// pairs) — and to 338 frames of 41 tracked presses, all checked at native pixels (session 40; held out by
    /// object it puts the truth inside the 50 / 90 / 95 % regions in 50 / 88 / 93 % of those pairs, where the
    /// model-resolution calibration put it in 69 / 95 / 97 %: docs/uncertainty.md). The fusion weight is the other's
    /// 0.15: the fit preferred 0, but its tracks' regions scored the same at 0.15 (−14.69 nats a frame either way),
    /// and 0.15 picks better than independent frames where a frame prefers another pose by little (session 37).
    pub fn resampled_frames_bundled() -> Self {
        Self {
            temperature: 3.48,
            covariance_temperature: 1.62,
            floor_position_m: 1.81e-5,
            floor_theta_rad: 0.00426,
            floor_exponent: 1.05,
            frame_noise: true,
            noise_floor_m: 6.76e-4,
            tail_logit: -1.49,
            tail_contact_slope: -0.274,
            tail_position_m: 1.7e-5,
            tail_theta_rad: 0.0512,
            tail_exponent: 0.26,
            tail_core_scale: 2.99,
            far_logit: -5.68,
            far_contact_slope: 0.336,
            far_position_m: 0.00541,
            far_exponent: 0.187,
            far_ambiguity: 0.825,
            tail_rivals: 0.505,
            far_rivals: 1.36,
            tail_misfit: 5.53,
            far_misfit: 6.09,
            ..Self::model_resolution_bundled()
        }
    }

    /// A calibration read from a file written before [`Self::resampled_frames`] existed (a workbench session holds
    /// the whole pose configuration): where it is the bundled one for frames made at the model's resolution, it was
    /// the bundled default when saved, and is now the whole bundled default, resampled frames' calibration included.
    /// Any other calibration is returned as it is (one for every frame).
    pub fn upgraded(self) -> Self {
        if self == Self::model_resolution_bundled() {
            Self::default()
        } else {
            self
        }
    }

    /// The calibration for frames that were `resampled` from the camera's native pixels and checked at them
    /// ([`Self::resampled_frames`] where given), or for frames made at the model's resolution (this one).
    pub fn for_frames(&self, resampled: bool) -> &Self {
        match (&self.resampled_frames, resampled) {
            (Some(r), true) => r,
            _ => self,
        }
    }

    /// The likelihood as its parametric model states it: every pixel independent (τ = τ_c = 1), no floors, no tails
    /// (the "raw" rows of docs/uncertainty.md); the other settings the defaults.
    pub fn untempered() -> Self {
        Self {
            temperature: 1.0,
            covariance_temperature: 1.0,
            floor_position_m: 0.0,
            floor_theta_rad: 0.0,
            tail_logit: -50.0,
            far_logit: -50.0,
            resampled_frames: None,
            ..Self::default()
        }
    }

    /// The factor [`Self::frame_noise`] multiplies the evidence by for a frame with `noise` (1 when off).
    pub fn evidence_scale(&self, noise: Option<&super::posterior::FrameNoise>) -> f64 {
        let Some(n) = noise.filter(|_| self.frame_noise) else {
            return 1.0;
        };
        let assumed = n.assumed_m * n.assumed_m;
        let frame = if n.measured_m.is_finite() && n.measured_m > 0.0 {
            n.measured_m * n.measured_m
        } else {
            assumed
        };
        let k = assumed / (frame + self.noise_floor_m * self.noise_floor_m);
        if k.is_finite() && k > 0.0 {
            k
        } else {
            1.0
        }
    }

    /// A posterior calibration from a JSON file (every field optional, the defaults for the others), checked. The
    /// error says what is wrong; the caller names the file.
    pub fn read(path: &Path) -> Result<Self, InvalidInput> {
        const WHAT: &str = "posterior calibration";
        let text = crate::io::input::read_text_capped(path, crate::io::input::MAX_SETTINGS_BYTES)
            .map_err(|e| InvalidInput::new(WHAT, format!("cannot read: {e}")))?;
        let config: Self = serde_json::from_str(&text)
            .map_err(|e| InvalidInput::new(WHAT, format!("not a posterior calibration: {e}")))?;
        config
            .validate()
            .map_err(|e| InvalidInput::new(WHAT, e.to_string()))?;
        Ok(config)
    }

    /// Every setting in range; the error names the first that is not.
    pub fn validate(&self) -> Result<(), super::PoseError> {
        super::check_settings(
            "posterior: ",
            &[
                ("temperature", self.temperature),
                ("covariance_temperature", self.covariance_temperature),
                ("step_m", self.step_m),
                ("lever_m", self.lever_m),
                ("max_sigma_m", self.max_sigma_m),
                ("floor_contact_px", self.floor_contact_px),
                ("contact_threshold_m", self.contact_threshold_m),
                ("rival_window_nats", self.rival_window_nats),
            ],
            &[
                ("floor_exponent", self.floor_exponent),
                ("floor_position_m", self.floor_position_m),
                ("floor_theta_rad", self.floor_theta_rad),
                ("min_weight", self.min_weight),
                ("tail_position_m", self.tail_position_m),
                ("tail_theta_rad", self.tail_theta_rad),
                ("far_position_m", self.far_position_m),
                ("tail_core_scale", self.tail_core_scale),
                ("noise_floor_m", self.noise_floor_m),
            ],
        )?;
        for (name, value) in [
            ("tail_exponent", self.tail_exponent),
            ("far_exponent", self.far_exponent),
            ("far_ambiguity", self.far_ambiguity),
            ("tail_logit", self.tail_logit),
            ("tail_contact_slope", self.tail_contact_slope),
            ("far_logit", self.far_logit),
            ("far_contact_slope", self.far_contact_slope),
            ("tail_rivals", self.tail_rivals),
            ("far_rivals", self.far_rivals),
            ("tail_misfit", self.tail_misfit),
            ("far_misfit", self.far_misfit),
        ] {
            if !value.is_finite() || value.abs() > 50.0 {
                return Err(super::PoseError::Config(format!(
                    "posterior: {name} must be a finite number between -50 and 50 (got {value})"
                )));
            }
        }
        // Upper bounds: past them the covariances overflow (null in JSON) and coverage reads 0 %.
        for (name, value, max, why) in [
            (
                "temperature",
                self.temperature,
                1e6,
                "a posterior that trusts no pixel",
            ),
            (
                "covariance_temperature",
                self.covariance_temperature,
                1e6,
                "a posterior that trusts no pixel",
            ),
            (
                "tail_position_m",
                self.tail_position_m,
                1.0,
                "beyond any sensor's reach",
            ),
            (
                "far_position_m",
                self.far_position_m,
                1.0,
                "beyond any sensor's reach",
            ),
            (
                "tail_theta_rad",
                self.tail_theta_rad,
                std::f64::consts::TAU,
                "more than a turn",
            ),
            (
                "floor_position_m",
                self.floor_position_m,
                1.0,
                "beyond any sensor's reach",
            ),
            (
                "floor_theta_rad",
                self.floor_theta_rad,
                std::f64::consts::TAU,
                "more than a turn",
            ),
            (
                "max_sigma_m",
                self.max_sigma_m,
                1.0,
                "beyond any sensor's reach",
            ),
            ("lever_m", self.lever_m, 1.0, "beyond any sensor's reach"),
            (
                "noise_floor_m",
                self.noise_floor_m,
                0.1,
                "deeper than the sensor",
            ),
            ("step_m", self.step_m, 0.01, "wider than a contact"),
            (
                "rival_window_nats",
                self.rival_window_nats,
                1e6,
                "every pose a rival",
            ),
            (
                "contact_threshold_m",
                self.contact_threshold_m,
                0.1,
                "deeper than the sensor",
            ),
            (
                "floor_exponent",
                self.floor_exponent,
                4.0,
                "steeper than any contact law",
            ),
            (
                "floor_contact_px",
                self.floor_contact_px,
                1e7,
                "more pixels than an image has",
            ),
        ] {
            if value > max {
                let show = |v: f64| {
                    if v.abs() >= 1e5 {
                        format!("{v:e}")
                    } else {
                        format!("{v}")
                    }
                };
                return Err(super::PoseError::Config(format!(
                    "posterior: {name} {} is above {} ({why})",
                    show(value),
                    show(max)
                )));
            }
        }
        if !(0.0..=1.0).contains(&self.fusion_weight) {
            return Err(super::PoseError::Config(format!(
                "posterior: fusion_weight must be between 0 and 1 (got {})",
                self.fusion_weight
            )));
        }
        if self.max_modes == 0 || self.min_weight >= 1.0 {
            return Err(super::PoseError::Config(
                "posterior: max_modes must be at least 1 and min_weight below 1".into(),
            ));
        }
        match &self.resampled_frames {
            Some(r) if r.resampled_frames.is_some() => Err(super::PoseError::Config(
                "posterior: resampled_frames cannot hold a resampled_frames of its own".into(),
            )),
            Some(r) => r.validate().map_err(|e| {
                let e = e.to_string();
                let setting = e.strip_prefix("posterior: ").unwrap_or(&e);
                super::PoseError::Config(format!("posterior: resampled_frames.{setting}"))
            }),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resampled_frames_get_their_own_calibration_unless_a_file_gives_one_for_all() {
        let bundled = PosteriorConfig::default();
        let resampled = PosteriorConfig::resampled_frames_bundled();
        assert_eq!(bundled.for_frames(true), &resampled);
        assert_ne!(bundled.for_frames(false), &resampled);
        assert!(bundled.for_frames(false).resampled_frames.is_some());
        assert!(resampled.resampled_frames.is_none());
        bundled.validate().unwrap();
        // A calibration file (as `tnd posterior --fit` writes one, or a user's partial one) is for every frame.
        let file: PosteriorConfig = serde_json::from_str(r#"{"temperature": 2.5}"#).unwrap();
        assert!(file.resampled_frames.is_none());
        assert_eq!(file.for_frames(true), &file);
        assert_eq!(file.for_frames(false), &file);
        // The bundled one survives a session file's round trip, both calibrations.
        let text = serde_json::to_string(&bundled).unwrap();
        assert_eq!(
            serde_json::from_str::<PosteriorConfig>(&text).unwrap(),
            bundled
        );
        let written = serde_json::to_string(&resampled).unwrap();
        assert!(!written.contains("resampled_frames"), "{written}");
        // A session saved before the field existed held the bundled calibration without it: it is the bundled one.
        let saved_before = PosteriorConfig::model_resolution_bundled();
        assert_eq!(saved_before.upgraded(), bundled);
        assert_eq!(file.clone().upgraded(), file);
    }

    #[test]
    fn a_bad_setting_of_the_resampled_calibration_is_named_by_its_path() {
        let mut c = PosteriorConfig::default();
        if let Some(r) = c.resampled_frames.as_mut() {
            r.temperature = -1.0;
        }
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.starts_with("posterior: resampled_frames.temperature"),
            "{e}"
        );
        let mut nested = PosteriorConfig::default();
        if let Some(r) = nested.resampled_frames.as_mut() {
            r.resampled_frames = Some(Box::new(PosteriorConfig::resampled_frames_bundled()));
        }
        let e = nested.validate().unwrap_err().to_string();
        assert!(e.contains("cannot hold a resampled_frames"), "{e}");
    }
}
