//! **Drift**: the membrane changes between the no-contact frames and a contact (air leaks, temperature), which is
//! why labs record an undeformed frame before every grasp. A recording's no-contact frames come in stretches (before
//! the first press, between presses, after the last); each stretch's median frame is a reference, and its drift is
//! how far the membrane's central half moved from the first stretch's (mean depth change, metres; positive: away
//! from the camera, more inflated). When the stretches disagree by more than [`DRIFT_TOLERANCE_M`], each frame's
//! imprint is taken against the references of the stretches before and after it, blended by its time
//! ([`LocalReference`]: a membrane that drifts steadily, as a slow leak or warming does), instead of one reference for
//! the whole recording.

use serde::Serialize;

use crate::image::Image;

/// Drift between no-contact stretches beyond which each contact gets its own reference from the stretches around it,
/// metres (0.3 mm: a fifth of the signature's noise, and under the 1 mm at which the imprint's contact area starts to
/// grow by whole rims of pixels at the 3 mm contact threshold).
pub const DRIFT_TOLERANCE_M: f64 = 3e-4;

/// Drift beyond which a contact far from its reference stretch may be off by a contact threshold's worth, metres:
/// front ends warn past it.
pub const DRIFT_WARNING_M: f64 = 1e-3;

/// The part of the membrane a drift is fitted on to find the no-contact frames: [`profile`] below this.
pub const OUTER_PROFILE: f32 = 0.6;

/// Least frames of a stretch that make it a reference of its own (fewer: a flicker between contacts).
pub const MIN_STRETCH_FRAMES: usize = 3;

/// One run of consecutive no-contact frames and the reference it gives.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct QuietStretch {
    /// First and last frame (inclusive, 0-based).
    pub first: usize,
    pub last: usize,
    /// The frames the reference is the median of (the stretch's last ones, nearest the next contact).
    pub reference_frames: Vec<usize>,
    /// The membrane's drift from the first stretch, metres (module docs).
    pub drift_m: f64,
    #[serde(skip)]
    pub reference: Image,
}

/// Runs of consecutive frames in the sorted list `quiet`, with at least [`MIN_STRETCH_FRAMES`] frames each.
pub fn runs(quiet: &[usize]) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for &k in quiet {
        match out.last_mut() {
            Some((_, last)) if *last + 1 == k => *last = k,
            _ => out.push((k, k)),
        }
    }
    out.retain(|&(a, b)| b + 1 - a >= MIN_STRETCH_FRAMES);
    out
}

/// The mean depth change from `first` to `other` over the membrane's central half (the pixels where `first` is
/// deeper than its median: the part nearest the apex, which inflation moves most), metres; 0 without shared pixels.
pub fn drift_between(first: &Image, other: &Image) -> f64 {
    let mut depths: Vec<f32> = first.data.iter().copied().filter(|&d| d > 0.0).collect();
    if depths.is_empty() {
        return 0.0;
    }
    let mid = depths.len() / 2;
    let (_, &mut median, _) = depths.select_nth_unstable_by(mid, f32::total_cmp);
    let (sum, n) = first
        .data
        .iter()
        .zip(&other.data)
        .filter(|(&a, &b)| a >= median && a > 0.0 && b > 0.0)
        .fold((0.0f64, 0usize), |(s, n), (&a, &b)| {
            (s + f64::from(b) - f64::from(a), n + 1)
        });
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// The shape a drift takes on the membrane seen as `reference` (metres): 0 where the membrane is nearest the camera
/// (its rim), 1 where it is deepest (its apex), in between in proportion to the depth — inflation moves the apex
/// most and the clamped rim not at all. 0 where not measured.
pub fn profile(reference: &Image) -> Vec<f32> {
    // The 1st and 99th percentiles of the depth, so that a stray return does not squash the shape.
    let mut depths: Vec<f32> = reference
        .data
        .iter()
        .copied()
        .filter(|&d| d > 0.0)
        .collect();
    if depths.is_empty() {
        return vec![0.0; reference.data.len()];
    }
    depths.sort_by(f32::total_cmp);
    let at = |q: f64| depths[((depths.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (at(0.01), at(0.99));
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    reference
        .data
        .iter()
        .map(|&d| {
            if d > 0.0 {
                ((d - lo) / span).clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
        .collect()
}

/// `y` (an imprint against a reference whose drift [`profile`] is `shape`) less its least-squares fit a·shape + b
/// over the pixels where `measured` holds (the residual is of every pixel): what a drift of the whole membrane
/// cannot explain (a contact, noise). Returns the residual and the fitted a (metres of drift at the apex, sign of
/// the imprint).
pub fn without_drift(y: &Image, shape: &[f32], measured: impl Fn(usize) -> bool) -> (Image, f64) {
    let (mut n, mut sx, mut sy, mut sxx, mut sxy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
    for (i, (&v, &x)) in y.data.iter().zip(shape).enumerate() {
        if measured(i) {
            let (x, v) = (f64::from(x), f64::from(v));
            n += 1.0;
            sx += x;
            sy += v;
            sxx += x * x;
            sxy += x * v;
        }
    }
    let det = n * sxx - sx * sx;
    if n < 2.0 || det.abs() < 1e-12 * n * n {
        return (y.clone(), 0.0);
    }
    let a = (n * sxy - sx * sy) / det;
    let b = (sy - a * sx) / n;
    let mut out = y.clone();
    for (v, &x) in out.data.iter_mut().zip(shape) {
        *v = (f64::from(*v) - a * f64::from(x) - b) as f32;
    }
    (out, a)
}

/// How one frame's reference is made of the no-contact stretches' references: the membrane is taken to drift
/// steadily between two stretches, so a frame between them gets their references blended by its time, and a frame
/// before the first or after the last stretch that stretch's reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LocalReference {
    /// The last stretch whose time (the mean time of its reference frames) is at or before the frame's (the first
    /// stretch for frames before every stretch's time).
    pub before: usize,
    /// The next stretch (`before` itself for frames before the first stretch's time or after the last's).
    pub after: usize,
    /// Weight of `after`'s reference, 0..=1: how far the frame's time is from `before`'s reference frames towards
    /// `after`'s.
    pub weight: f64,
}

impl LocalReference {
    /// The reference this describes, from `stretches` (`None` if it names a stretch that is not there).
    pub fn blend<'a>(&self, stretches: &'a [QuietStretch]) -> Option<std::borrow::Cow<'a, Image>> {
        let a = &stretches.get(self.before)?.reference;
        let b = &stretches.get(self.after)?.reference;
        if self.after == self.before || self.weight <= 0.0 {
            return Some(std::borrow::Cow::Borrowed(a));
        }
        if self.weight >= 1.0 {
            return Some(std::borrow::Cow::Borrowed(b));
        }
        Some(std::borrow::Cow::Owned(blend(a, b, self.weight)))
    }
}

/// `a` and `b` (depth frames, 0 where not measured) blended as `(1 − weight)·a + weight·b`; where one of them did not
/// measure a pixel, the other's value.
pub fn blend(a: &Image, b: &Image, weight: f64) -> Image {
    let w = weight as f32;
    a.zip_map(b, |x, y| match (x > 0.0, y > 0.0) {
        (true, true) => x + w * (y - x),
        (true, false) => x,
        (false, true) => y,
        (false, false) => 0.0,
    })
}

/// Per frame (time stamps `stamps_ns`), its [`LocalReference`] among `stretches` (in order): the stretches' times
/// are the mean time of their reference frames. Stamps that do not increase through the recording (repeated, or
/// out of order) are not a clock: the frames' numbers are used instead.
pub fn local_references(stretches: &[QuietStretch], stamps_ns: &[u64]) -> Vec<LocalReference> {
    let t0 = stamps_ns.first().copied().unwrap_or(0);
    let clock =
        stamps_ns.windows(2).all(|w| w[0] <= w[1]) && stamps_ns.last().is_some_and(|&t| t > t0);
    let time = |k: usize| {
        if clock {
            stamps_ns
                .get(k)
                .map_or(0.0, |&t| t.saturating_sub(t0) as f64)
        } else {
            k as f64
        }
    };
    let centres: Vec<f64> = stretches
        .iter()
        .map(|s| {
            let n = s.reference_frames.len().max(1) as f64;
            s.reference_frames.iter().map(|&k| time(k)).sum::<f64>() / n
        })
        .collect();
    (0..stamps_ns.len())
        .map(|k| {
            let t = time(k);
            let before = centres.iter().rposition(|&c| c <= t).unwrap_or(0);
            match centres.get(before + 1) {
                Some(&next) if centres[before] <= t && next > centres[before] => LocalReference {
                    before,
                    after: before + 1,
                    weight: ((t - centres[before]) / (next - centres[before])).clamp(0.0, 1.0),
                },
                _ => LocalReference {
                    before,
                    after: before,
                    weight: 0.0,
                },
            }
        })
        .collect()
}

/// The largest drift between any two stretches, metres (0 with one stretch): the spread of their drifts.
pub fn largest_drift(stretches: &[QuietStretch]) -> f64 {
    spread(stretches.iter().map(|s| s.drift_m))
}

/// The spread (largest minus smallest) of drifts measured from a first stretch, whose own drift is 0.
pub fn spread(drifts: impl Iterator<Item = f64>) -> f64 {
    let (lo, hi) = drifts.fold((0.0f64, 0.0f64), |(lo, hi), d| (lo.min(d), hi.max(d)));
    hi - lo
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn stretches_are_runs_of_enough_frames() {
        assert_eq!(
            runs(&[0, 1, 2, 3, 7, 9, 10, 11, 20, 21]),
            vec![(0, 3), (9, 11)]
        );
        assert!(runs(&[]).is_empty());
    }

    #[test]
    fn drift_is_the_central_halfs_mean_change() {
        // A dome: deeper in the middle. Inflated by 1 mm at the middle, 0 at the rim.
        let dome = Image::from_vec(5, 1, vec![0.06, 0.07, 0.08, 0.07, 0.06]).unwrap();
        let mut inflated = dome.clone();
        *inflated.get_mut(2, 0) += 0.001;
        *inflated.get_mut(1, 0) += 0.0005;
        *inflated.get_mut(3, 0) += 0.0005;
        // Central half: pixels at or above the median depth 0.07 (three of them): mean (0.5 + 1 + 0.5) / 3 mm.
        let d = drift_between(&dome, &inflated);
        assert!((d - 2e-3 / 3.0).abs() < 1e-6, "{d}");
        assert!(drift_between(&dome, &dome).abs() < 1e-12);
        let s = |first: usize, last: usize| QuietStretch {
            first,
            last,
            reference_frames: vec![],
            drift_m: first as f64 * 1e-4,
            reference: dome.clone(),
        };
        let stretches = [s(0, 4), s(10, 14), s(20, 24)];
        assert!((largest_drift(&stretches) - 2e-3).abs() < 1e-12);
        // Two later stretches 0.2 mm either side of the first are 0.4 mm apart.
        let mut apart = [s(0, 4), s(10, 14), s(20, 24)];
        apart[1].drift_m = 2e-4;
        apart[2].drift_m = -2e-4;
        assert!((largest_drift(&apart) - 4e-4).abs() < 1e-12);
    }

    #[test]
    fn a_drift_of_the_membrane_is_removed_and_a_contact_is_not() {
        // A dome 21 pixels across: 60 mm deep at its rims, 80 mm at its apex (pixel 10).
        let dome = |i: usize| 0.06 + 0.02 * (1.0 - ((i as f32 - 10.0) / 10.0).powi(2));
        let r = Image::from_vec(21, 1, (0..21).map(dome).collect()).unwrap();
        let shape = profile(&r);
        assert_eq!((shape[0], shape[10], shape[20]), (0.0, 1.0, 0.0));
        // An imprint of a 1.5 mm deflation (the apex 1.5 mm nearer, the rim not): explained entirely.
        let drift = Image::from_vec(21, 1, shape.iter().map(|&x| 0.0015 * x).collect()).unwrap();
        let (rest, a) = without_drift(&drift, &shape, |_| true);
        assert!((a - 0.0015).abs() < 1e-9, "{a}");
        assert!(rest.data.iter().all(|v| v.abs() < 1e-7));
        // The same with a 4 mm contact on the three pixels at the apex: fitted on every pixel, the contact passes for
        // part of a drift, but much of it stays.
        let mut pressed = drift.clone();
        for v in &mut pressed.data[9..12] {
            *v += 0.004;
        }
        let (rest, _) = without_drift(&pressed, &shape, |_| true);
        assert!(
            rest.data[10] > 0.002 && rest.data[10] < 0.0035,
            "{}",
            rest.data[10]
        );
        // Fitted on the outer part only, the drift is found exactly and the contact stays whole.
        let (rest, a) = without_drift(&pressed, &shape, |i| shape[i] < OUTER_PROFILE);
        assert!((a - 0.0015).abs() < 1e-6, "{a}");
        assert!((rest.data[10] - 0.004).abs() < 1e-6, "{}", rest.data[10]);
    }

    #[test]
    fn a_frame_between_two_stretches_blends_their_references_by_its_time() {
        // Stretches at frames 0-3 and 10-13 (reference frames 2, 3 and 12, 13: times 2.5 and 12.5 at 1 frame/s);
        // a membrane 90 mm deep in the first, 89 mm in the second; pixel 1 not measured in the second, pixel 2 in
        // neither.
        let stretch = |first: usize, frames: Vec<usize>, depth: f32| QuietStretch {
            first,
            last: first + 3,
            reference_frames: frames,
            drift_m: 0.0,
            reference: Image::from_vec(
                3,
                1,
                vec![depth, if first == 0 { depth } else { 0.0 }, 0.0],
            )
            .unwrap(),
        };
        let stretches = [
            stretch(0, vec![2, 3], 0.090),
            stretch(10, vec![12, 13], 0.089),
        ];
        let stamps: Vec<u64> = (0..16).map(|k| 1_000 + k * 1_000_000_000).collect();
        let of = local_references(&stretches, &stamps);
        let at = |k: usize| (of[k].before, of[k].after, of[k].weight);
        assert_eq!(
            at(0),
            (0, 0, 0.0),
            "before the first stretch: its reference"
        );
        assert_eq!((at(5).0, at(5).1), (0, 1));
        assert!((at(5).2 - 0.25).abs() < 1e-9, "{:?}", at(5));
        assert!((at(10).2 - 0.75).abs() < 1e-9);
        assert_eq!(at(14), (1, 1, 0.0), "after the last stretch: its reference");
        let r = of[5].blend(&stretches).unwrap();
        assert!((r.data[0] - 0.08975).abs() < 1e-7, "{}", r.data[0]);
        assert_eq!(
            r.data[1], 0.090,
            "measured in one reference only: that one's value"
        );
        assert_eq!(r.data[2], 0.0, "measured in neither: missing");
        assert_eq!(
            of[14].blend(&stretches).unwrap().data,
            stretches[1].reference.data
        );
        // Stamps that are not a clock (all the same) fall back to the frame numbers: the same weights here.
        let unstamped = local_references(&stretches, &[7; 16]);
        assert_eq!(unstamped, of);
    }
}
