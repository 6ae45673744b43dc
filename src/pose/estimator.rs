//! The **pose engine** (paper IV.C, extended): one [`Estimator`] owns every step between an in-contact depth
//! estimate and a pose — anchoring the estimate's contact depths onto the measured signature, the K-start
//! registration with free-space evidence, pooling the hypotheses of several estimates, the signature check with its
//! refinement, and the posterior ([`super::choose`]) — configured by one [`PoseConfig`]. `PoseConfig` is clap +
//! serde: `tnd eval`, `tnd pose` and `tnd recording track` flatten it into their options and the workbench stores it
//! in its sessions, so a setting means the same everywhere. Scoring against a true pose is `metrics`'; the pose use
//! case that places the sensor and runs this engine is `pipeline::place_and_estimate`.

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};

use clap::ArgAction;
use glam::{DAffine3, DVec3};
use serde::{Deserialize, Serialize};

use super::from_depth::{anchor_to_signature, SensorView};
use super::posterior::PosteriorConfig;
use super::signature_check::{SignatureCheckConfig, SignatureModel};
use super::{
    sample_surface, BaselineConfig, Hypothesis, InitStrategy, PoseError, SdfRegistration,
    SdfRegistrationConfig,
};
use crate::error::InvalidInput;
use crate::image::Image;
use crate::mesh::{Mesh, RayCaster};
use crate::objects::{ObjectSet, Symmetry};
use crate::recon::FreeSpaceConfig;
use crate::sensor::{Intrinsics, Se2};

/// The value of `--posterior` that names the bundled calibration ([`PosteriorConfig::default`]).
pub const BUNDLED_POSTERIOR: &str = "bundled";

/// Settings of the pose engine. On the command line: `--inits`, `--no-anchor`, `--no-signature-check`,
/// `--no-imprint-proposals`, `--check-refine` and `--posterior FILE`; the others are set in session or config files
/// (serde, every field optional).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default)]
pub struct PoseConfig {
    /// The registration's solver settings.
    #[arg(skip = SdfRegistrationConfig::default())]
    pub registration: SdfRegistrationConfig,
    /// Where free-space points are placed along each camera ray.
    #[arg(skip = FreeSpaceConfig::default())]
    pub free_space: FreeSpaceConfig,
    /// The threshold baseline (the imprint's own contact).
    #[arg(skip = BaselineConfig::default())]
    pub baseline: BaselineConfig,
    /// Random starts per registration (the paper's K = 10).
    ///
    /// With the signature check more starts give it more hypotheses to choose from.
    #[arg(long, default_value_t = DEFAULT_INITS)]
    pub inits: usize,
    /// Random starts are within this distance of the contact centroid, metres (default 10 mm).
    #[arg(skip = DEFAULT_INIT_RADIUS_M)]
    pub init_radius_m: f64,
    /// Fraction of the samples that must mark a pixel as contact for their consensus, the multi-sample estimate's
    /// contact (default 0.5).
    #[arg(skip = DEFAULT_CONSENSUS_PROBABILITY)]
    pub consensus_probability: f64,
    /// Depth anchoring (on; `--no-anchor` registers the estimates as generated).
    ///
    /// Every estimate's contact depths are shifted onto the measured signature before registration, which
    /// removes the offset a drifted membrane inflation gives (`pose::from_depth::anchor_to_signature`). Depth
    /// metrics score the estimate as generated.
    #[arg(long = "no-anchor", action = ArgAction::SetFalse)]
    pub anchor_to_signature: bool,
    /// The signature check (on; `--no-signature-check` takes the registration's lowest-cost hypothesis).
    ///
    /// Each hypothesis predicts the signature; the best explanation is refined and kept
    /// (`pose::signature_check`). Needs the signature and the sensor's signature model.
    #[arg(long = "no-signature-check", action = ArgAction::SetFalse)]
    pub check_signature: bool,
    /// Settings of the signature check (`--check-refine`).
    #[command(flatten)]
    pub signature_check: SignatureCheckConfig,
    /// Imprint proposals (on, with the check; `--no-imprint-proposals` checks the sample's hypotheses alone).
    ///
    /// The threshold baseline's registration hypotheses join the sample's, so that where the imprint says more
    /// than a sample (small, shallow contacts) its pose can win. `tnd eval` scores it as a row of its own.
    #[arg(long = "no-imprint-proposals", action = ArgAction::SetFalse)]
    pub imprint_proposals: bool,
    /// A posterior calibration (JSON, as `tnd posterior --fit` writes) instead of the bundled one.
    ///
    /// It sets how the signature check's evidence becomes a pose posterior (`pose::posterior`), whose regions
    /// the outputs and `tnd eval`'s coverage report.
    #[arg(long = "posterior", value_name = "FILE", default_value = BUNDLED_POSTERIOR,
          value_parser = parse_posterior, hide_default_value = true)]
    pub posterior: PosteriorConfig,
}

/// Default of [`PoseConfig::inits`].
pub const DEFAULT_INITS: usize = 10;
/// Default of [`PoseConfig::init_radius_m`], metres.
pub const DEFAULT_INIT_RADIUS_M: f64 = 0.01;
/// Default of [`PoseConfig::consensus_probability`].
pub const DEFAULT_CONSENSUS_PROBABILITY: f64 = 0.5;

impl Default for PoseConfig {
    fn default() -> Self {
        Self {
            registration: SdfRegistrationConfig::default(),
            free_space: FreeSpaceConfig::default(),
            baseline: BaselineConfig::default(),
            inits: DEFAULT_INITS,
            init_radius_m: DEFAULT_INIT_RADIUS_M,
            consensus_probability: DEFAULT_CONSENSUS_PROBABILITY,
            anchor_to_signature: true,
            check_signature: true,
            signature_check: SignatureCheckConfig::default(),
            imprint_proposals: true,
            posterior: PosteriorConfig::default(),
        }
    }
}

/// Most random starts per registration (each holds its own registration state; 10^8 took gigabytes).
pub const MAX_INITS: usize = 10_000;

impl PoseConfig {
    /// The posterior calibration for frames of the sensor in `ctx`: the one for resampled frames
    /// ([`PosteriorConfig::resampled_frames`]) where they reached the model's resolution from the camera's native
    /// pixels and the check predicts them there, else [`Self::posterior`].
    pub fn posterior_for(&self, ctx: &SensorContext) -> &PosteriorConfig {
        self.posterior
            .for_frames(ctx.camera_path.is_some() && self.signature_check.native)
    }

    /// Every setting in range (a session or config file can hold any number); the error names the first that is
    /// not.
    pub fn validate(&self) -> Result<(), PoseError> {
        if !(1..=MAX_INITS).contains(&self.inits) {
            return Err(PoseError::Config(format!(
                "pose: inits must be 1..={MAX_INITS} (random starts per registration), got {}",
                self.inits
            )));
        }
        if !(self.consensus_probability > 0.0 && self.consensus_probability <= 1.0) {
            return Err(PoseError::Config(format!(
                "pose: consensus_probability must be in (0, 1], got {}",
                self.consensus_probability
            )));
        }
        super::check_settings("pose: ", &[], &[("init_radius_m", self.init_radius_m)])?;
        self.registration.validate()?;
        self.signature_check.validate()?;
        self.posterior.validate()
    }
}

/// `--posterior`: [`BUNDLED_POSTERIOR`] or a calibration file.
fn parse_posterior(value: &str) -> Result<PosteriorConfig, InvalidInput> {
    if value == BUNDLED_POSTERIOR {
        return Ok(PosteriorConfig::default());
    }
    PosteriorConfig::read(Path::new(value))
}

/// What the estimator knows about the sensor the estimates come from: the camera, the undeformed membrane depth E
/// (free-space evidence) and the signature model; and the object set the objects are named in.
#[derive(Clone, Debug)]
pub struct SensorContext {
    pub intrinsics: Intrinsics,
    /// E: depth of the undeformed membrane, metres (0 where not seen).
    pub membrane: Image,
    pub objects: ObjectSet,
    /// How a contact becomes a signature on this sensor (the shadow cloak), for the signature check; `None` when
    /// unknown (the check is then skipped).
    pub signature_model: Option<SignatureModel>,
    /// Pixels of the measurement without a return ([`Self::observing`]): no free-space evidence there. `None`: every
    /// pixel measured.
    pub unmeasured: Option<std::sync::Arc<Vec<bool>>>,
    /// The camera's native pixels, for frames that reached this resolution by area resampling (the signature
    /// check then predicts them the same way, [`super::camera_path`]); `None`: frames made at this resolution.
    pub camera_path: Option<std::sync::Arc<super::camera_path::CameraPath>>,
}

impl SensorContext {
    /// The camera and undeformed membrane of `sim`'s sensor, with `objects`.
    pub fn of_simulator(sim: &crate::sim::Simulator, objects: ObjectSet) -> Self {
        Self {
            intrinsics: *sim.intrinsics(),
            membrane: sim.nominal_depth().clone(),
            objects,
            signature_model: Some(SignatureModel::of_simulator(sim)),
            unmeasured: None,
            camera_path: None,
        }
    }
}

impl SensorContext {
    /// This context as a measurement with signature `signature` (metres, the camera's size) sees the sensor: the
    /// pixels where the frame has no return but the membrane is seen are marked [`Self::unmeasured`], so that the
    /// registration claims no free space on a pixel the camera did not measure (the signature check keeps the whole
    /// membrane for its predictions; its cost leaves those pixels out itself). Borrowed when nothing is missing.
    pub fn observing(&self, signature: Option<&Image>) -> std::borrow::Cow<'_, SensorContext> {
        use std::borrow::Cow;
        let Some(s) = signature.filter(|s| s.data.len() == self.membrane.data.len()) else {
            return Cow::Borrowed(self);
        };
        let missing: Vec<bool> = self
            .membrane
            .data
            .iter()
            .zip(&s.data)
            .map(|(&e, &d)| e > 0.0 && !crate::image::is_measured_depth(d))
            .collect();
        if !missing.iter().any(|&m| m) {
            return Cow::Borrowed(self);
        }
        let mut ctx = self.clone();
        ctx.unmeasured = Some(std::sync::Arc::new(missing));
        Cow::Owned(ctx)
    }

    /// The membrane depth the registration's free space is placed on: E, 0 where [`Self::unmeasured`].
    pub fn free_space_membrane(&self) -> std::borrow::Cow<'_, Image> {
        use std::borrow::Cow;
        match &self.unmeasured {
            Some(m) if m.len() == self.membrane.data.len() => {
                let mut e = self.membrane.clone();
                for (d, &gone) in e.data.iter_mut().zip(m.iter()) {
                    if gone {
                        *d = 0.0;
                    }
                }
                Cow::Owned(e)
            }
            _ => Cow::Borrowed(&self.membrane),
        }
    }
}

/// An object prepared for registration, the signature check and scoring.
pub struct ObjectModel {
    pub registration: SdfRegistration,
    /// Surface samples (object frame) for the Chamfer distance.
    pub cloud: Vec<DVec3>,
    pub symmetry: Symmetry,
    /// Ray caster of the mesh (object frame) for the signature check.
    pub caster: RayCaster,
}

/// A hash of `mesh`'s vertices and triangles: the same name with another mesh (a workbench that loaded a new file)
/// is not served the old one's model.
fn mesh_fingerprint(mesh: &Mesh) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for v in mesh.vertices() {
        [v.x, v.y, v.z].map(f32::to_bits).hash(&mut h);
    }
    mesh.triangles().hash(&mut h);
    h.finish()
}

/// What earlier observations of the same contact say about the pose: a track's previous frame, whose object has
/// not moved (the sensor presses it against the table). The registrations start from its poses (plus a few random
/// starts, so that a pose it missed can still be found) and the press search stays near its press.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PosePrior {
    /// Poses `t_world_object` to start from, most likely first.
    pub poses: Vec<Se2>,
    /// Random starts beside them.
    pub random_starts: usize,
    /// The press the sensor was at, metres (`None`: found from the samples as without a prior).
    pub press_m: Option<f64>,
    /// The earlier frames' pose posterior: it reweighs this observation's modes ([`super::fusion::fuse`]).
    #[serde(default)]
    pub posterior: Option<super::posterior::PosePosterior>,
}

impl PosePrior {
    /// The same prior without random starts: the registrations after the first (imprint proposals, the
    /// multi-sample estimate) start from the carried poses alone; the first one explores.
    pub fn carried_only(&self) -> PosePrior {
        PosePrior {
            random_starts: 0,
            ..self.clone()
        }
    }
}

/// Default of the surface samples per object ([`Estimator::with_surface_points`]).
pub const DEFAULT_SURFACE_POINTS: usize = 1000;

/// The pose engine (module docs); caches one [`ObjectModel`] per object name.
pub struct Estimator {
    pub config: PoseConfig,
    surface_points: usize,
    objects: Mutex<HashMap<String, Arc<ObjectModel>>>,
}

impl Estimator {
    pub fn new(config: PoseConfig) -> Self {
        Self {
            config,
            surface_points: DEFAULT_SURFACE_POINTS,
            objects: Mutex::new(HashMap::new()),
        }
    }

    /// Sample `n` points on each object's surface for [`ObjectModel::cloud`] (default [`DEFAULT_SURFACE_POINTS`]).
    pub fn with_surface_points(mut self, n: usize) -> Self {
        self.surface_points = n;
        self
    }

    /// The prepared object `name` of `set` (built on first use).
    pub fn object(&self, set: &ObjectSet, name: &str) -> Result<Arc<ObjectModel>, PoseError> {
        if let Some(m) = self.objects.lock().ok().and_then(|m| m.get(name).cloned()) {
            return Ok(m);
        }
        let mesh = set.mesh(name)?;
        let symmetry = set.find(name).map(|e| e.symmetry).unwrap_or_default();
        self.object_from_mesh(name, &mesh, symmetry)
    }

    /// Prepare (and cache under `name`) an object given by its mesh (object frame, resting pose) and symmetry; the
    /// cached model when this estimator has prepared the same mesh under that name before (a track's frames, a
    /// press search and the estimate after it build the SDF grid once).
    pub fn object_from_mesh(
        &self,
        name: &str,
        mesh: &Mesh,
        symmetry: Symmetry,
    ) -> Result<Arc<ObjectModel>, PoseError> {
        let key = format!("{name}#{:016x}", mesh_fingerprint(mesh));
        if let Some(m) = self.objects.lock().ok().and_then(|m| m.get(&key).cloned()) {
            if m.symmetry == symmetry {
                return Ok(m);
            }
        }
        let registration = SdfRegistration::new(mesh, self.config.registration.clone())?;
        let caster = RayCaster::new(mesh)?;
        let model = Arc::new(ObjectModel {
            registration,
            cloud: sample_surface(mesh, self.surface_points, 0),
            symmetry,
            caster,
        });
        if let Ok(mut m) = self.objects.lock() {
            m.insert(name.to_string(), model.clone());
            m.insert(key, model.clone());
        }
        Ok(model)
    }

    /// The registration's starts: [`PoseConfig::inits`] random poses within [`PoseConfig::init_radius_m`] of the
    /// contact centroid, drawn from `seed`.
    pub fn random_starts(&self, seed: u64) -> InitStrategy {
        InitStrategy::Random {
            count: self.config.inits,
            radius_m: self.config.init_radius_m,
            seed,
        }
    }

    /// The registration's starts for an observation with `prior`: its poses and [`PosePrior::random_starts`]
    /// random ones; [`Self::random_starts`] without a prior (or one without poses).
    pub fn starts(&self, seed: u64, prior: Option<&PosePrior>) -> InitStrategy {
        match prior.filter(|p| !p.poses.is_empty()) {
            Some(p) => InitStrategy::Carried {
                starts: p.poses.clone(),
                random: p.random_starts,
                radius_m: self.config.init_radius_m,
                seed,
            },
            None => self.random_starts(seed),
        }
    }

    /// Register `object` to an in-contact depth image: every hypothesis, best first; `None` without contact
    /// ([`super::from_depth::register_depth`] with this estimator's free-space settings).
    pub fn register_depth(
        &self,
        object: &ObjectModel,
        x0: &Image,
        ctx: &SensorContext,
        t_world_camera: &DAffine3,
        strategy: &InitStrategy,
        seed: u64,
    ) -> Result<Option<Vec<Hypothesis>>, PoseError> {
        let membrane = ctx.free_space_membrane();
        let view = SensorView {
            intrinsics: &ctx.intrinsics,
            membrane: &membrane,
            t_world_camera,
        };
        super::from_depth::register_depth(
            &object.registration,
            x0,
            &view,
            &self.config.free_space,
            strategy,
            seed,
        )
    }

    /// The estimates `samples` as registered: with [`PoseConfig::anchor_to_signature`] and a signature, each one's
    /// contact depths moved onto it where the imprint says contact ([`anchor_to_signature`]), with the shifts
    /// (metres); otherwise unchanged, with no shifts.
    pub fn anchor(
        &self,
        samples: &[Image],
        signature: Option<&Image>,
        imprint: &Image,
    ) -> Result<(Vec<Image>, Vec<f64>), PoseError> {
        match signature {
            Some(s) if self.config.anchor_to_signature => samples
                .iter()
                .map(|x| anchor_to_signature(x, s, imprint))
                .collect(),
            _ => Ok((samples.to_vec(), Vec::new())),
        }
    }

    /// Every image of `estimates` anchored to `anchor_to` = (signature, imprint) ([`Self::anchor`]; `None`: as
    /// given) and registered from `strategy`'s starts: the hypotheses of all of them, each image's best first, in
    /// the order of `estimates` (images without contact give none).
    pub fn pooled_hypotheses(
        &self,
        object: &ObjectModel,
        estimates: &[Image],
        ctx: &SensorContext,
        t_world_camera: &DAffine3,
        anchor_to: Option<(&Image, &Image)>,
        strategy: &InitStrategy,
    ) -> Result<Vec<Hypothesis>, PoseError> {
        let seed = match strategy {
            InitStrategy::Random { seed, .. } | InitStrategy::Carried { seed, .. } => *seed,
            InitStrategy::Fixed(_) => 0,
        };
        let (anchored, _) = match anchor_to {
            Some((signature, imprint)) => self.anchor(estimates, Some(signature), imprint)?,
            None => (estimates.to_vec(), Vec::new()),
        };
        let mut hypotheses = Vec::new();
        for x0 in &anchored {
            let hyps = self.register_depth(object, x0, ctx, t_world_camera, strategy, seed)?;
            hypotheses.extend(hyps.unwrap_or_default());
        }
        Ok(hypotheses)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// A command with the pose options, as `tnd pose`, `tnd eval` and `tnd recording track` flatten them.
    #[derive(Parser, Debug)]
    struct Cli {
        #[command(flatten)]
        pose: PoseConfig,
    }

    fn parse(args: &[&str]) -> Result<PoseConfig, clap::Error> {
        Cli::try_parse_from(std::iter::once("tnd").chain(args.iter().copied())).map(|c| c.pose)
    }

    #[test]
    fn an_object_is_prepared_once_per_mesh_and_again_for_another_mesh_of_that_name() {
        let set = ObjectSet::builtin();
        let names: Vec<String> = set
            .entries()
            .iter()
            .take(2)
            .map(|e| e.name.clone())
            .collect();
        let (a, b) = (set.mesh(&names[0]).unwrap(), set.mesh(&names[1]).unwrap());
        let engine = Estimator::new(PoseConfig::default()).with_surface_points(10);
        let first = engine
            .object_from_mesh("obj", &a, Symmetry::default())
            .unwrap();
        let again = engine
            .object_from_mesh("obj", &a, Symmetry::default())
            .unwrap();
        assert!(
            Arc::ptr_eq(&first, &again),
            "the same mesh is served from the cache"
        );
        let other = engine
            .object_from_mesh("obj", &b, Symmetry::default())
            .unwrap();
        assert!(
            !Arc::ptr_eq(&first, &other),
            "another mesh under the same name is prepared anew"
        );
        // By name (the object set's lookup) the latest one.
        assert!(Arc::ptr_eq(&engine.object(&set, "obj").unwrap(), &other));
    }

    #[test]
    fn pixels_without_a_return_give_no_free_space_and_keep_the_membrane() {
        let ctx = SensorContext {
            intrinsics: crate::sim::SimConfig::default()
                .camera
                .intrinsics()
                .resized(3, 1),
            membrane: Image::from_vec(3, 1, vec![0.09, 0.09, 0.0]).unwrap(),
            objects: ObjectSet::builtin(),
            signature_model: None,
            unmeasured: None,
            camera_path: None,
        };
        // Every seen pixel measured (the unseen one is not the frame's to measure): nothing changes.
        let full = Image::from_vec(3, 1, vec![0.08, 0.09, 0.0]).unwrap();
        assert!(matches!(
            ctx.observing(Some(&full)),
            std::borrow::Cow::Borrowed(_)
        ));
        // Pixel 1 without a return: no free space on it; the membrane itself stays for the signature check.
        let holed = Image::from_vec(3, 1, vec![0.08, 0.0, 0.0]).unwrap();
        let seen = ctx.observing(Some(&holed));
        assert_eq!(seen.membrane, ctx.membrane);
        assert_eq!(seen.free_space_membrane().data, vec![0.09, 0.0, 0.0]);
        assert_eq!(ctx.free_space_membrane().data, ctx.membrane.data);
    }

    #[test]
    fn the_command_lines_defaults_are_the_configs_defaults() {
        // Two ways to the defaults (clap's attributes and `Default`) must agree, field by field.
        assert_eq!(parse(&[]).unwrap(), PoseConfig::default());
        let json: PoseConfig = serde_json::from_str("{}").unwrap();
        assert_eq!(json, PoseConfig::default());
    }

    #[test]
    fn each_option_sets_its_setting_and_only_it() {
        let c = parse(&[
            "--no-anchor",
            "--no-signature-check",
            "--no-imprint-proposals",
            "--inits",
            "4",
            "--check-refine",
            "3",
        ])
        .unwrap();
        let expected = PoseConfig {
            anchor_to_signature: false,
            check_signature: false,
            imprint_proposals: false,
            inits: 4,
            signature_check: SignatureCheckConfig {
                refine: 3,
                ..SignatureCheckConfig::default()
            },
            ..PoseConfig::default()
        };
        assert_eq!(c, expected);
        // Serialized and read back (a session, a track's settings), the same settings.
        let back: PoseConfig = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, expected);
        // A partial file keeps the defaults for what it does not name.
        let partial: PoseConfig = serde_json::from_str(r#"{"check_signature": false}"#).unwrap();
        assert!(!partial.check_signature && partial.anchor_to_signature && partial.inits == 10);
    }

    #[test]
    fn settings_out_of_range_are_named() {
        assert!(PoseConfig::default().validate().is_ok());
        let bad = |edit: &dyn Fn(&mut PoseConfig), name: &str| {
            let mut c = PoseConfig::default();
            edit(&mut c);
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains(name), "{name}: {e}");
        };
        bad(&|c| c.inits = 0, "inits");
        bad(&|c| c.consensus_probability = 1.5, "consensus_probability");
        bad(
            &|c| c.consensus_probability = f64::NAN,
            "consensus_probability",
        );
        bad(&|c| c.init_radius_m = -0.01, "init_radius_m");
        bad(&|c| c.signature_check.scale_m = 0.0, "scale_m");
        bad(&|c| c.posterior.temperature = -1.0, "temperature");
        bad(&|c| c.registration.lever_m = f64::INFINITY, "lever_m");
    }

    #[test]
    fn posterior_files_are_read_checked_and_named_in_errors() {
        let dir = tempfile::tempdir().unwrap();
        let good = dir.path().join("fit.json");
        std::fs::write(&good, r#"{"temperature": 8.0}"#).unwrap();
        let c = parse(&["--posterior", good.to_str().unwrap()]).unwrap();
        assert_eq!(c.posterior.temperature, 8.0);
        assert_eq!(c.posterior.max_modes, PosteriorConfig::default().max_modes);
        assert_eq!(
            parse(&["--posterior", BUNDLED_POSTERIOR]).unwrap(),
            PoseConfig::default()
        );
        let cases = [
            (r#"{"temperature": "hot"}"#, "not a posterior calibration"),
            (r#"{"temperature": -1.0}"#, "temperature must be positive"),
            (r#"{"no_such_setting": 1}"#, "unknown field"),
            // Overflowing settings (the covariances came out null, coverage 0 %).
            (
                r#"{"floor_position_m": 1e160}"#,
                "floor_position_m 1e160 is above 1",
            ),
            (
                r#"{"temperature": 1e308}"#,
                "temperature 1e308 is above 1e6",
            ),
        ];
        for (text, expected) in cases {
            let bad = dir.path().join("bad.json");
            std::fs::write(&bad, text).unwrap();
            let e = parse(&["--posterior", bad.to_str().unwrap()]).unwrap_err();
            let e = e.to_string();
            assert!(e.contains(expected) && e.contains("bad.json"), "{e}");
            assert_eq!(e.matches("bad.json").count(), 1, "the path once: {e}");
        }
        let missing = dir.path().join("missing.json");
        let e = parse(&["--posterior", missing.to_str().unwrap()])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("cannot read") && e.contains("missing.json"),
            "{e}"
        );
    }
}
