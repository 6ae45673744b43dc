//! The measured images of `tnd pose` and `tnd sample`: an imprint, or a signature with its no-contact reference
//! frame(s), at the sensor's native resolution (e.g. 224 x 171, as a driver publishes them), its crop, or the model
//! resolution — brought to the model resolution with the crop and area resampling every recording goes through.
//! Native reference frames also calibrate the sensor ([`tactile_derender::recording::calibrate`]), so that
//! guidance, anchoring and the signature check use the membrane that was measured, not the nominal one.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use clap::Args;
use tactile_derender::dataset::resample;
use tactile_derender::image::Image;
use tactile_derender::io::npy;
use tactile_derender::recording::calibrate::{
    calibrate_references, mean_image, CalibrateConfig, SensorCalibration,
};
use tactile_derender::recording::process::{measured_pixels, too_few_returns};
use tactile_derender::sim::signature::imprint as imprint_of;
use tactile_derender::sim::SimConfig;

/// Where the measured images come from.
#[derive(Args, Debug, Clone)]
pub struct MeasuredArgs {
    /// The imprint Y = R − S (.npy, metres): native (e.g. 224x171), cropped, or at the model resolution. Not needed
    /// with --signature and --reference.
    #[arg(long)]
    pub imprint: Option<PathBuf>,
    /// The signature S (.npy, metres), as --imprint: for imprint guidance, the threshold baseline and the signature
    /// check.
    #[arg(long)]
    pub signature: Option<PathBuf>,
    /// A frame of the sensor touching nothing (.npy, metres; repeat for several, they are averaged): with
    /// --signature it gives the imprint R − S, and it calibrates the sensor (membrane, camera position; the noise
    /// too from two or more frames) unless --no-calibrate.
    #[arg(long)]
    pub reference: Vec<PathBuf>,
    /// Use the sensor as given even when --reference frames could calibrate it.
    #[arg(long, conflicts_with = "calibrate")]
    pub no_calibrate: bool,
    /// Re-fit a sensor given with --sensor from the --reference frames. Without it a sensor file is used as it is
    /// (one or two frames fit the inflation less well than the recording it came from); without a sensor file the
    /// references always calibrate the nominal sensor.
    #[arg(long)]
    pub calibrate: bool,
}

/// The measured images at the model resolution, and the sensor they were measured with.
pub struct Measured {
    pub imprint: Image,
    pub signature: Option<Image>,
    /// The sensor: as given, or calibrated from the reference frames.
    pub sim: SimConfig,
    pub calibration: Option<SensorCalibration>,
    /// Whether the frames were brought to the model resolution by area resampling from a camera's larger frame
    /// (what `--model auto` picks its model by).
    pub resampled: bool,
}

/// An image file (.npy, metres) at the native, cropped or model resolution of `sim`'s camera, at the model resolution.
pub fn read_model(path: &Path, sim: &SimConfig) -> Result<Image> {
    let img = npy::read_metres_image(path)?;
    resample::to_model(&sim.camera, &img).map_err(|e| anyhow!("{}: {e}", path.display()))
}

/// A depth frame (.npy, metres), saying on stderr how many of its pixels have no return (NaN, ±inf, 0, negative or
/// out of range: missing, left out by every stage).
fn read_frame(path: &Path) -> Result<Image> {
    let (img, missing) = npy::read_metres_image(path)?.missing_as_zero();
    if missing > 0 {
        eprintln!(
            "{}: {missing} of {} pixels without a return, read as missing",
            path.display(),
            img.data.len()
        );
    }
    Ok(img)
}

impl MeasuredArgs {
    /// The files these options read.
    pub fn inputs(&self) -> Vec<&Path> {
        let mut v: Vec<&Path> = [self.imprint.as_deref(), self.signature.as_deref()]
            .into_iter()
            .flatten()
            .collect();
        v.extend(self.reference.iter().map(PathBuf::as_path));
        v
    }

    /// Read the images for the sensor `given` (calibrated from the references where there are any, unless it came
    /// from a sensor file, `from_file`, and --calibrate is not given). With `imprint_any_size`, an imprint alone (no
    /// signature, no reference) of a size no stage of the sensor has is taken as it is (`tnd sample` with a model
    /// of another resolution; the model checks its size).
    pub fn read(
        &self,
        given: SimConfig,
        from_file: bool,
        imprint_any_size: bool,
    ) -> Result<Measured> {
        let mut references = Vec::with_capacity(self.reference.len());
        for p in &self.reference {
            references.push(read_frame(p)?);
        }
        // The frames' sizes as read, before any resampling.
        let mut sizes: Vec<(usize, usize)> =
            references.iter().map(|r| (r.width, r.height)).collect();
        let refit = !self.no_calibrate && (self.calibrate || !from_file);
        let calibration = if references.is_empty() || !refit {
            None
        } else {
            let (cal, _) =
                calibrate_references(references.clone(), &given, &CalibrateConfig::default())
                    .map_err(|e| anyhow!("--reference {}: {e}", self.reference[0].display()))?;
            crate::calibrate_cmd::tell_calibration(&self.reference[0], Some(&cal), None);
            Some(cal)
        };
        let sim = calibration.as_ref().map_or(given, |c| c.sensor.clone());
        let signature = self
            .signature
            .as_deref()
            .map(|p| {
                let frame = read_frame(p)?;
                sizes.push((frame.width, frame.height));
                resample::to_model(&sim.camera, &frame).map_err(|e| anyhow!("{}: {e}", p.display()))
            })
            .transpose()?;
        let imprint = match (&self.imprint, &signature, references.is_empty()) {
            (Some(p), _, _) => {
                let img = npy::read_metres_image(p)?;
                sizes.push((img.width, img.height));
                let model = resample::to_model(&sim.camera, &img);
                if imprint_any_size && signature.is_none() && references.is_empty() {
                    model.unwrap_or(img)
                } else {
                    model.map_err(|e| anyhow!("{}: {e}", p.display()))?
                }
            }
            (None, Some(s), false) => {
                let model: Vec<Image> = references
                    .iter()
                    .zip(&self.reference)
                    .map(|(r, p)| resample::to_model(&sim.camera, r).map_err(|e| anyhow!("{}: {e}", p.display())))
                    .collect::<Result<_>>()?;
                let reference = mean_image(&model.iter().collect::<Vec<_>>());
                if let Some(why) = too_few_returns(measured_pixels(&reference, s), reference.count_nonzero()) {
                    let path = self.signature.as_deref().unwrap_or(Path::new("--signature"));
                    bail!("{}: {why}: too few to de-render", path.display());
                }
                imprint_of(&reference, s)
            }
            _ => bail!("give the imprint (--imprint Y.npy), or the signature and a frame without contact (--signature S.npy --reference R.npy)"),
        };
        if let Some(s) = &signature {
            if (s.width, s.height) != (imprint.width, imprint.height) {
                bail!("the signature and the imprint differ in size after resampling");
            }
        }
        let resampled = sizes
            .iter()
            .any(|&(w, h)| resample::is_resampled(&sim.camera, w, h));
        Ok(Measured {
            imprint,
            signature,
            sim,
            calibration,
            resampled,
        })
    }
}
