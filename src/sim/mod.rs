//! The contact-depth **simulator** (paper IV.A) and synthetic tactile signatures (V.A).
//!
//! Stages, one module each: [`render`] (1. object depth rendering, and the elastomer's nominal depth E),
//! [`contact`] (2. depth projection to 3D, 3. signed distance to the elastomer, 4. contact mask and in-contact depth),
//! [`shadows`] (tactile-shadow cloak) and [`signature`] (noise, reference, imprint); [`calibration`] sweeps the
//! membrane's inflation against a measurement; [`sensor_file`] reads and writes a whole sensor as JSON. [`Simulator`] runs them in order
//! for one scene; everything that depends only on the sensor (membrane BVH and SDF, E) is built once.

pub mod bounds;
pub mod calibration;
pub mod contact;
pub mod depth_camera;
pub mod render;
pub mod sensor_file;
pub mod shadows;
pub mod signature;

use std::time::Instant;

use glam::DAffine3;
use serde::{Deserialize, Serialize};

use crate::image::Image;
use crate::mesh::{Mesh, MeshError, RayCaster, SignedDistance};
use crate::sensor::pose::CameraMount;
use crate::sensor::{
    CameraConfig, ElastomerConfig, ElastomerError, Intrinsics, Scene, Se2, SensorPose,
};
pub use depth_camera::DepthCameraConfig;
pub use signature::SignatureConfig;

/// Press depth of the membrane apex below the object's highest point that every front end starts from (`tnd sim`,
/// `tnd pose`, the workbench's scene), metres: the same everywhere, so that a pose run on a simulated contact places
/// the sensor where the simulation did unless told otherwise.
pub const DEFAULT_PRESS_M: f64 = 0.006;

/// Errors setting up or running the simulator.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("camera: {0}")]
    Camera(#[source] crate::error::InvalidSetting),
    #[error("signature: {0}")]
    Signature(#[source] crate::error::InvalidSetting),
    #[error("sensor setting {}: {}", .0.setting, .0.message)]
    Bounds(#[source] crate::error::InvalidSetting),
    /// A depth camera setting out of range (its message names the `depth_camera.` setting).
    #[error("{0}")]
    DepthCamera(#[source] crate::error::InvalidSetting),
    #[error(transparent)]
    Elastomer(#[from] ElastomerError),
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

/// Everything that defines the simulated sensor.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SimConfig {
    pub camera: CameraConfig,
    pub mount: CameraMount,
    pub elastomer: ElastomerConfig,
    pub signature: SignatureConfig,
    /// The depth camera's artefacts beyond the signature's noise (missing returns, depth-dependent noise, flying
    /// pixels, a fixed pattern), applied to native frames ([`depth_camera`]); left out of files when ideal.
    #[serde(skip_serializing_if = "DepthCameraConfig::is_ideal")]
    pub depth_camera: DepthCameraConfig,
}

/// An object mesh prepared for rendering (BVH built once; reuse it across poses).
pub struct PreparedObject {
    pub mesh: Mesh,
    caster: RayCaster,
    /// Height of the object's highest point above the table in its resting pose, metres.
    pub top_z: f64,
    /// Where that highest point is, object frame (x, y), metres.
    pub top_xy: [f64; 2],
}

impl PreparedObject {
    /// Prepare a mesh in its resting pose (object frame, lowest point at z = 0).
    pub fn new(mesh: Mesh) -> Result<Self, MeshError> {
        let caster = RayCaster::new(&mesh)?;
        let top = mesh
            .vertices()
            .iter()
            .copied()
            .max_by(|a, b| a.z.total_cmp(&b.z))
            .unwrap_or_default();
        Ok(Self {
            mesh,
            caster,
            top_z: f64::from(top.z),
            top_xy: [f64::from(top.x), f64::from(top.y)],
        })
    }
}

/// The object's highest point seen from the membrane's apex ([`Simulator::contact_hint`]): what to tell a user
/// whose scene makes no contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactHint {
    /// Horizontal distance from the apex to the object's highest point, metres.
    pub offset_m: f64,
    /// How far the apex sits below that point, metres (negative: above it).
    pub press_m: f64,
    /// The object pose, θ kept, that puts the highest point under the apex.
    pub centred: Se2,
}

impl std::fmt::Display for ContactHint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.press_m <= 0.0 {
            write!(
                f,
                "the membrane's apex is {:.1} mm above the object's highest point: press deeper",
                self.press_m.abs() * 1e3
            )
        } else {
            write!(
                f,
                "the object's highest point is {:.1} mm sideways of the membrane's apex, which sits {:.1} mm below \
                 it; the object at x = {:.1} mm, y = {:.1} mm (θ kept) puts that point under the apex",
                self.offset_m * 1e3,
                self.press_m * 1e3,
                self.centred.x * 1e3,
                self.centred.y * 1e3
            )
        }
    }
}

/// All images of one simulated contact, row-major at the model resolution, metres.
#[derive(Clone, Debug, PartialEq)]
pub struct SimOutput {
    /// D: z-depth of the object from the sensor camera (0 = miss).
    pub depth: Image,
    /// E: nominal (undeformed) elastomer depth (0 = membrane not seen).
    pub elastomer: Image,
    /// M: contact mask (1 where the object point lies inside the membrane).
    pub mask: Image,
    /// X0 = M ⊙ D: in-contact depth, the model's target.
    pub target: Image,
    /// S: synthetic signature (with shadows and noise).
    pub signature: Image,
    /// R: reference (E with its own noise).
    pub reference: Image,
    /// Y = R − S: the imprint, the model's condition.
    pub imprint: Image,
    /// Number of pixels in contact.
    pub contact_pixels: usize,
}

/// The simulator for one sensor configuration.
pub struct Simulator {
    config: SimConfig,
    intrinsics: Intrinsics,
    t_sensor_camera: DAffine3,
    elastomer_mesh: Mesh,
    elastomer_sdf: contact::ElastomerSdf,
    nominal: Image,
    apex_height: f64,
    spacing: (f64, f64),
}

impl Simulator {
    /// Validate the configuration, build the membrane and its SDF, and render E.
    pub fn new(config: SimConfig) -> Result<Self, SimError> {
        config.camera.validate().map_err(SimError::Camera)?;
        let intrinsics = config.camera.intrinsics();
        Self::with_intrinsics(config, intrinsics)
    }

    /// The same sensor rendering the camera's whole **native** frame (e.g. 224 x 171, no crop, no resampling), as a
    /// real recording holds it; the signature noise is then per native pixel.
    pub fn native(mut config: SimConfig) -> Result<Self, SimError> {
        config.camera.validate().map_err(SimError::Camera)?;
        let native = config.camera.native;
        config.camera.crop_rows = (0, native.height);
        config.camera.crop_cols = (0, native.width);
        config.camera.resolution = (native.width, native.height);
        Self::with_intrinsics(config, native)
    }

    fn with_intrinsics(config: SimConfig, intrinsics: Intrinsics) -> Result<Self, SimError> {
        // The bounds that need no mesh first: an absurd membrane is not built.
        bounds::check_settings(&config).map_err(SimError::Bounds)?;
        config.signature.validate().map_err(SimError::Signature)?;
        config
            .depth_camera
            .validate()
            .map_err(SimError::DepthCamera)?;
        let t_sensor_camera = config.mount.t_sensor_camera();
        let elastomer_mesh = config.elastomer.build()?;
        let caster = RayCaster::new(&elastomer_mesh)?;
        let nominal = render::render_far_depth(&caster, &intrinsics, &t_sensor_camera);
        bounds::check_membrane(&config, &elastomer_mesh, &nominal).map_err(SimError::Bounds)?;
        // The parametric membrane's contact test answers from its half-ellipsoid wherever that is certain.
        let e = &config.elastomer;
        let dome = e.mesh_file.is_none().then(|| {
            let axes = glam::DVec3::new(e.footprint_x / 2.0, e.footprint_y / 2.0, e.inflation);
            contact::DomeBounds::new(&elastomer_mesh, axes)
        });
        let elastomer_sdf = contact::ElastomerSdf::new(
            SignedDistance::new(&elastomer_mesh)?,
            elastomer_mesh.aabb(),
        )
        .with_dome(dome.flatten());
        let apex_height = config.elastomer.apex_height(&elastomer_mesh);
        let spacing = intrinsics.pixel_size_in(&config.camera.native);
        Ok(Self {
            config,
            intrinsics,
            t_sensor_camera,
            elastomer_mesh,
            elastomer_sdf,
            nominal,
            apex_height,
            spacing,
        })
    }

    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Intrinsics of the rendered images.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// `t_sensor_camera`.
    pub fn t_sensor_camera(&self) -> DAffine3 {
        self.t_sensor_camera
    }

    /// The membrane mesh in the sensor frame.
    pub fn elastomer_mesh(&self) -> &Mesh {
        &self.elastomer_mesh
    }

    /// E: the nominal elastomer depth image.
    pub fn nominal_depth(&self) -> &Image {
        &self.nominal
    }

    /// Height of the membrane apex above its base, metres.
    pub fn apex_height(&self) -> f64 {
        self.apex_height
    }

    /// Why `scene` may show no contact: where the object's highest point lies from the membrane's apex, and the
    /// object pose (same θ) that puts it right under the apex.
    pub fn contact_hint(&self, object: &PreparedObject, scene: &Scene) -> ContactHint {
        let apex = scene
            .sensor
            .t_world_sensor()
            .transform_point3(glam::DVec3::new(0.0, 0.0, self.apex_height));
        let [x, y] = object.top_xy;
        let top = scene
            .object
            .to_affine()
            .transform_point3(glam::DVec3::new(x, y, object.top_z));
        let (dx, dy) = (apex.x - top.x, apex.y - top.y);
        ContactHint {
            offset_m: dx.hypot(dy),
            press_m: top.z - apex.z,
            centred: Se2::new(scene.object.x + dx, scene.object.y + dy, scene.object.theta),
        }
    }

    /// Sensor pose above the sensor-frame origin `(x, y)` pressing the apex `press` metres into the object's top.
    pub fn pressing_pose(
        &self,
        object: &PreparedObject,
        x: f64,
        y: f64,
        yaw: f64,
        press: f64,
    ) -> SensorPose {
        SensorPose::pressing(x, y, yaw, [0.0, 0.0], self.apex_height, object.top_z, press)
    }

    /// `t_world_camera` for a sensor pose.
    pub fn t_world_camera(&self, sensor: &SensorPose) -> DAffine3 {
        sensor.t_world_sensor() * self.t_sensor_camera
    }

    /// Step 1: D for the object at `scene.object` seen from `scene.sensor`.
    pub fn render_depth(&self, object: &PreparedObject, scene: &Scene) -> Image {
        let t_object_camera =
            scene.object.to_affine().inverse() * self.t_world_camera(&scene.sensor);
        render::render_depth(&object.caster, &self.intrinsics, &t_object_camera)
    }

    /// Steps 2–4 on a depth image: contact mask M and in-contact depth X0.
    pub fn contact(&self, depth: &Image) -> (Image, Image) {
        contact::contact(
            depth,
            &self.intrinsics,
            &self.t_sensor_camera,
            &self.elastomer_sdf,
        )
    }

    /// The whole pipeline for one scene; `seed` drives the signature noise.
    pub fn simulate(&self, object: &PreparedObject, scene: &Scene, seed: u64) -> SimOutput {
        let depth = self.render_depth(object, scene);
        let (mask, target) = self.contact(&depth);
        let sig = signature::synthesize(
            &depth,
            &self.nominal,
            &mask,
            &self.config.signature,
            self.spacing,
            seed,
        );
        let contact_pixels = mask.count_nonzero();
        SimOutput {
            depth,
            elastomer: self.nominal.clone(),
            mask,
            target,
            signature: sig.signature,
            reference: sig.reference,
            imprint: sig.imprint,
            contact_pixels,
        }
    }

    /// [`Self::simulate`] with its wall time in seconds.
    pub fn simulate_timed(
        &self,
        object: &PreparedObject,
        scene: &Scene,
        seed: u64,
    ) -> (SimOutput, f64) {
        let t0 = Instant::now();
        let out = self.simulate(object, scene, seed);
        (out, t0.elapsed().as_secs_f64())
    }
}
