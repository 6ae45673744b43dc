//! **Saved samples** of an evaluation (`tnd eval --save-samples DIR`): for each scored pair, what the model saw and
//! drew, as an uncompressed `.npz` that `numpy.load` opens — the imprint Y, the signature S, the true in-contact
//! depth X0 and the model's N samples X̂0 (metres, 0 off contact, as generated: before depth anchoring), with the
//! object's true pose. A pair `unseen_objects/12` goes to `DIR/unseen_objects/12.npz`; its scores are the record of
//! the same name in `--records`.
//!
//! ```python
//! z = numpy.load("DIR/unseen_objects/12.npz")
//! z["samples"].shape      # (N, H, W); z["samples"][0] is the sample the single-sample rows score
//! ```

use std::path::{Path, PathBuf};

use super::evaluate::{EvalError, EvalPair};
use crate::dataset::npz::{self, ArrayData};
use crate::image::Image;

/// Where pair `pair_name` (e.g. `unseen_objects/12`) is saved under `dir`.
pub fn samples_path(dir: &Path, pair_name: &str) -> PathBuf {
    let mut path = dir.to_path_buf();
    for part in pair_name.split('/').filter(|p| !p.is_empty() && *p != "..") {
        path.push(part);
    }
    path.set_extension("npz");
    path
}

/// Write `pair` and its `samples` (all of the pair's size) to [`samples_path`] atomically, creating folders; returns
/// the path.
pub fn save_samples(dir: &Path, pair: &EvalPair, samples: &[Image]) -> Result<PathBuf, EvalError> {
    let path = samples_path(dir, &pair.name);
    let fail = |message: String| EvalError::Write {
        path: path.clone(),
        message,
    };
    let (w, h) = (pair.target.width, pair.target.height);
    if samples.is_empty() {
        return Err(fail("no samples to save".into()));
    }
    for (what, img) in [("imprint", &pair.imprint), ("signature", &pair.signature)]
        .into_iter()
        .chain(samples.iter().map(|s| ("sample", s)))
    {
        if (img.width, img.height) != (w, h) {
            return Err(fail(format!(
                "the {what} is {}x{} pixels, the target {w}x{h}",
                img.width, img.height
            )));
        }
    }
    let image = |name: &'static str, img: &Image| {
        ArrayData::f32(name, vec![h, w], img.data.iter().copied())
    };
    let pose = pair.object_pose;
    let arrays = [
        image("imprint", &pair.imprint),
        image("signature", &pair.signature),
        image("target", &pair.target),
        ArrayData::f32(
            "samples",
            vec![samples.len(), h, w],
            samples.iter().flat_map(|s| s.data.iter().copied()),
        ),
        ArrayData::f64("object_pose", vec![3], [pose.x, pose.y, pose.theta]),
    ];
    let bytes = npz::encode(&arrays).map_err(|e| fail(e.into()))?;
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)
            .map_err(|e| fail(format!("cannot create the folder: {e}")))?;
    }
    crate::io::write_atomic(&path, &bytes).map_err(|e| fail(format!("cannot write: {e}")))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pair_names_become_paths_inside_the_folder() {
        let dir = Path::new("out");
        assert_eq!(
            samples_path(dir, "unseen_objects/12"),
            Path::new("out/unseen_objects/12.npz")
        );
        // A hostile name cannot leave the folder.
        assert_eq!(samples_path(dir, "../../x"), Path::new("out/x.npz"));
    }
}
