//! Pairs **seen through the depth camera**: where the sensor has a depth camera model
//! ([`crate::sim::DepthCameraConfig`]: missing returns, depth-dependent noise, flying pixels, a fixed pattern), a
//! pair's signature and reference are rendered at the camera's native resolution, given the camera's artefacts and
//! brought to the model's resolution the way `tnd dataset import` brings a recording's frames
//! ([`crate::sensor::resample::to_model`]; the reference the per-pixel median of several no-contact frames, as the
//! recording's quiet frames; missing returns 0). The target and the contact mask stay the noise-free model-resolution
//! truth: what the camera does is the model's input, not its answer. A model trained on such pairs has seen the
//! frames a real sensor gives (issue 50: training data randomises the camera with a sensor variation's
//! `camera_artefacts`).

use crate::image::Image;
use crate::sensor::resample;
use crate::sensor::Scene;
use crate::sim::signature;
use crate::sim::{PreparedObject, SimConfig, SimError, Simulator};

/// No-contact frames whose per-pixel median is a pair's reference (a recording's quiet frames give 15 at most;
/// fewer keep generation cheap, and a median of 7 already removes the frames' own dropouts).
pub const REFERENCE_FRAMES: usize = 7;

/// A sensor's depth camera at its native resolution, for [`CameraPass::measure`].
pub struct CameraPass {
    native: Simulator,
    /// The sensor's camera as the model sees it (its crop and resolution; the native simulator's are the native
    /// image's).
    model_camera: crate::sensor::CameraConfig,
}

/// A pair's model inputs as the depth camera measures them, at the model's resolution (metres, 0 where missing).
pub struct Measured {
    pub imprint: Image,
    pub signature: Image,
    pub reference: Image,
}

impl CameraPass {
    /// The pass for `config`'s sensor; `None` when its depth camera is ideal (nothing to add to the model-resolution
    /// pair) unless `native_frames` asks for the native render and the import's resampling anyway.
    pub fn new(config: &SimConfig, native_frames: bool) -> Result<Option<Self>, SimError> {
        if config.depth_camera.is_ideal() && !native_frames {
            return Ok(None);
        }
        Ok(Some(Self {
            native: Simulator::native(config.clone())?,
            model_camera: config.camera.clone(),
        }))
    }

    /// The contact `scene` of `object` as the camera measures it, from `seed` (the signature's noise and the
    /// camera's artefacts; the reference frames from seeds derived from it).
    pub fn measure(&self, object: &PreparedObject, scene: &Scene, seed: u64) -> Measured {
        let config = self.native.config();
        let camera = &config.depth_camera;
        let noise = config.signature.noise_std;
        let depth = self.native.render_depth(object, scene);
        let (mask, _) = self.native.contact(&depth);
        // The native simulator's pixels are native pixels: the shadow's width needs no scaling.
        let spacing = self
            .native
            .intrinsics()
            .pixel_size_in(&config.camera.native);
        let sig = signature::synthesize(
            &depth,
            self.native.nominal_depth(),
            &mask,
            &config.signature,
            spacing,
            seed,
        );
        let to_model = |native: &Image| {
            // The native simulator's frames are the camera's native size, which the camera accepts by construction.
            resample::to_model(&self.model_camera, native).unwrap_or_else(|_| native.clone())
        };
        let signature = to_model(&camera.apply(&sig.signature, noise, seed));
        // No-contact frames: the undeformed membrane with the signature's noise and the camera's artefacts, each
        // from its own seed.
        let references: Vec<Image> = (0..REFERENCE_FRAMES as u64)
            .map(|k| {
                let frame_seed = crate::seed::mix64(seed ^ (k + 1).wrapping_mul(0x9E37));
                let quiet = with_noise(self.native.nominal_depth(), noise, frame_seed);
                to_model(&camera.apply(&quiet, noise, frame_seed))
            })
            .collect();
        let refs: Vec<&Image> = references.iter().collect();
        let reference = crate::recording::process::median_where_measured(&refs, 0.0);
        Measured {
            imprint: signature::imprint(&reference, &signature),
            signature,
            reference,
        }
    }
}

/// `depth` with independent Gaussian noise of standard deviation `noise_std` (metres) where it is seen.
fn with_noise(depth: &Image, noise_std: f64, seed: u64) -> Image {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut out = depth.clone();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    if let Ok(n) = Normal::new(0.0, noise_std.max(0.0)) {
        for d in out.data.iter_mut().filter(|d| **d > 0.0) {
            *d = (f64::from(*d) + n.sample(&mut rng)) as f32;
        }
    }
    out
}
