//! The circular histogram ("rose") of the samples' θ errors that the uncertainty figure and the workbench's Pose tab
//! draw: θ is an angle, so an error of +170° and one of −170° lie 20° apart, which only a circle shows. The object's
//! symmetry period goes once round the circle, no error at the top, positive (counter-clockwise) errors to the left;
//! each wedge's *area* is proportional to the samples in it (radius √(count / largest count)).

/// Wedges round the circle.
pub const ROSE_BINS: usize = 24;

/// The point at radius `r` in the direction of a θ error of `deg` degrees, for a symmetry period of `period_deg`.
pub fn rose_point(deg: f64, r: f64, period_deg: f64) -> [f64; 2] {
    let phi = std::f64::consts::FRAC_PI_2 + std::f64::consts::TAU * deg / period_deg;
    [r * phi.cos(), r * phi.sin()]
}

/// The wedge of each non-empty bin as a polygon (the centre, then 9 points along its arc), for θ errors in degrees
/// (wrapped to the period, non-finite ones left out); the bins are `period_deg / ROSE_BINS` wide, the first starting
/// at −period/2.
pub fn rose_wedges(errors_deg: &[f64], period_deg: f64) -> Vec<Vec<[f64; 2]>> {
    let half = period_deg / 2.0;
    let width = period_deg / ROSE_BINS as f64;
    let mut counts = [0usize; ROSE_BINS];
    for &e in errors_deg.iter().filter(|e| e.is_finite()) {
        let k = ((e + half) / width).floor().rem_euclid(ROSE_BINS as f64) as usize;
        counts[k.min(ROSE_BINS - 1)] += 1;
    }
    let most = counts.iter().copied().max().unwrap_or(0).max(1) as f64;
    counts
        .iter()
        .enumerate()
        .filter(|(_, &c)| c > 0)
        .map(|(k, &c)| {
            let r = (c as f64 / most).sqrt();
            let from = -half + k as f64 * width;
            let mut points = vec![[0.0, 0.0]];
            points
                .extend((0..=8).map(|j| rose_point(from + width * j as f64 / 8.0, r, period_deg)));
            points
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 2], b: [f64; 2]) -> bool {
        (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12
    }

    #[test]
    fn no_error_is_at_the_top_and_the_period_goes_round_once() {
        for period in [360.0, 180.0, 90.0] {
            assert!(close(rose_point(0.0, 1.0, period), [0.0, 1.0]));
            // A quarter period counter-clockwise is to the left; ± half a period meet at the bottom.
            assert!(close(rose_point(period / 4.0, 1.0, period), [-1.0, 0.0]));
            assert!(close(rose_point(period / 2.0, 1.0, period), [0.0, -1.0]));
            assert!(close(
                rose_point(period / 2.0, 2.0, period),
                rose_point(-period / 2.0, 2.0, period)
            ));
        }
    }

    #[test]
    fn wedge_areas_are_proportional_to_their_counts() {
        // 4 errors near 0, 1 near +90 (of 360): two wedges, areas 4 : 1 (a circular sector's area goes as r²).
        let wedges = rose_wedges(&[1.0, 2.0, 3.0, 4.0, 91.0, f64::NAN], 360.0);
        assert_eq!(wedges.len(), 2);
        let area = |w: &Vec<[f64; 2]>| {
            // Shoelace over the polygon (centre + arc): the sector's area up to the arc's chords.
            let n = w.len();
            (0..n)
                .map(|i| w[i][0] * w[(i + 1) % n][1] - w[(i + 1) % n][0] * w[i][1])
                .sum::<f64>()
                .abs()
                / 2.0
        };
        let ratio = area(&wedges[0]) / area(&wedges[1]);
        assert!((ratio - 4.0).abs() < 1e-9, "{ratio}");
        // The full wedge (4 samples) reaches the unit circle, in the bin [0°, 15°): to the left of the top.
        let tip = wedges[0][8];
        assert!(((tip[0].powi(2) + tip[1].powi(2)).sqrt() - 1.0).abs() < 1e-12);
        assert!(tip[0] < 0.0 && tip[1] > 0.9);
    }
}
