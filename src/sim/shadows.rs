//! Paper V.A, **tactile shadows**: around the contact region the real membrane does not drop straight back to its
//! nominal shape, so synthetic signatures get a "cloak": pixels within `shadow_px` of the contact region interpolate
//! linearly, by distance, from the depth of the nearest contact pixel to the nominal elastomer depth E.
//!
//! Distances come from an exact Euclidean distance transform with nearest-site tracking (Felzenszwalb & Huttenlocher
//! 2012, separable lower envelope of parabolas), with per-axis pixel spacing so that distances can be measured in the
//! sensor's native pixels whatever the model resolution.

use crate::image::Image;

/// Exact Euclidean distance from every pixel to the nearest pixel where `site` is true, with pixel spacing
/// `(sx, sy)`, and the flat index of that nearest site. Pixels have `(f64::INFINITY, None)` when there is no site.
pub fn distance_transform(
    width: usize,
    height: usize,
    site: &[bool],
    spacing: (f64, f64),
) -> Vec<(f64, Option<usize>)> {
    let (sx, sy) = spacing;
    // Pass 1: along each column, squared distance to the nearest site in that column and its row.
    let mut col_d2 = vec![f64::INFINITY; width * height];
    let mut col_row = vec![usize::MAX; width * height];
    let mut f = vec![f64::INFINITY; height];
    let mut out_d = vec![0.0; height.max(width)];
    let mut out_i = vec![0usize; height.max(width)];
    for u in 0..width {
        for v in 0..height {
            f[v] = if site[v * width + u] {
                0.0
            } else {
                f64::INFINITY
            };
        }
        lower_envelope(&f, sy, &mut out_d[..height], &mut out_i[..height]);
        for v in 0..height {
            col_d2[v * width + u] = out_d[v];
            col_row[v * width + u] = out_i[v];
        }
    }
    // Pass 2: along each row over the column results.
    let mut result = vec![(f64::INFINITY, None); width * height];
    let mut g = vec![0.0; width];
    for v in 0..height {
        g.copy_from_slice(&col_d2[v * width..(v + 1) * width]);
        lower_envelope(&g, sx, &mut out_d[..width], &mut out_i[..width]);
        for u in 0..width {
            let d2 = out_d[u];
            if d2.is_finite() {
                let su = out_i[u];
                let sv = col_row[v * width + su];
                result[v * width + u] = (d2.sqrt(), Some(sv * width + su));
            }
        }
    }
    result
}

/// 1-D squared distance transform: `d[p] = min_q (step * (p - q))^2 + f[q]`, and the minimising `q`.
fn lower_envelope(f: &[f64], step: f64, d: &mut [f64], arg: &mut [usize]) {
    let n = f.len();
    let sites: Vec<usize> = (0..n).filter(|&q| f[q].is_finite()).collect();
    if sites.is_empty() {
        d.fill(f64::INFINITY);
        arg.fill(usize::MAX);
        return;
    }
    let pos = |q: usize| q as f64 * step;
    let mut v: Vec<usize> = Vec::with_capacity(sites.len());
    let mut z: Vec<f64> = Vec::with_capacity(sites.len() + 1);
    for &q in &sites {
        loop {
            let Some(&r) = v.last() else {
                v.push(q);
                z.push(f64::NEG_INFINITY);
                break;
            };
            let s =
                ((f[q] + pos(q) * pos(q)) - (f[r] + pos(r) * pos(r))) / (2.0 * (pos(q) - pos(r)));
            if s <= z[z.len() - 1] {
                v.pop();
                z.pop();
            } else {
                v.push(q);
                z.push(s);
                break;
            }
        }
    }
    z.push(f64::INFINITY);
    let mut k = 0;
    for p in 0..n {
        while z[k + 1] < pos(p) {
            k += 1;
        }
        let q = v[k];
        d[p] = (pos(p) - pos(q)).powi(2) + f[q];
        arg[p] = q;
    }
}

/// The noise-free synthetic signature: D on the contact region, E elsewhere, except within `shadow_px` (measured with
/// pixel spacing `spacing`, e.g. native sensor pixels) of the contact region, where it goes linearly from the nearest
/// contact pixel's depth to E. Pixels where E is 0 (no membrane seen) stay 0.
pub fn tactile_signature(
    depth: &Image,
    nominal: &Image,
    mask: &Image,
    shadow_px: f64,
    spacing: (f64, f64),
) -> Image {
    let site: Vec<bool> = mask.data.iter().map(|&m| m > 0.5).collect();
    let dt = distance_transform(mask.width, mask.height, &site, spacing);
    let mut out = nominal.clone();
    for (i, px) in out.data.iter_mut().enumerate() {
        let e = nominal.data[i];
        if site[i] {
            *px = depth.data[i];
        } else if e > 0.0 {
            if let (d, Some(q)) = dt[i] {
                if d < shadow_px {
                    let w = (d / shadow_px) as f32;
                    *px = (1.0 - w) * depth.data[q] + w * e;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute_force(width: usize, height: usize, site: &[bool], s: (f64, f64)) -> Vec<f64> {
        (0..width * height)
            .map(|i| {
                let (u, v) = ((i % width) as f64, (i / width) as f64);
                (0..width * height)
                    .filter(|&j| site[j])
                    .map(|j| (((j % width) as f64 - u) * s.0).hypot(((j / width) as f64 - v) * s.1))
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    #[test]
    fn distance_transform_matches_brute_force() {
        let (w, h) = (23, 17);
        let mut state = 7u64;
        let site: Vec<bool> = (0..w * h)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
                (state >> 60) == 0
            })
            .collect();
        for spacing in [(1.0, 1.0), (2.734375, 2.1875)] {
            let dt = distance_transform(w, h, &site, spacing);
            let bf = brute_force(w, h, &site, spacing);
            for i in 0..w * h {
                assert!(
                    (dt[i].0 - bf[i]).abs() < 1e-9,
                    "pixel {i}: {} vs {}",
                    dt[i].0,
                    bf[i]
                );
                let q = dt[i].1.unwrap();
                assert!(site[q]);
                let d = (((q % w) as f64 - (i % w) as f64) * spacing.0)
                    .hypot(((q / w) as f64 - (i / w) as f64) * spacing.1);
                assert!(
                    (d - bf[i]).abs() < 1e-9,
                    "nearest site is not at the distance"
                );
            }
        }
        let none = distance_transform(4, 3, &[false; 12], (1.0, 1.0));
        assert!(none.iter().all(|(d, q)| d.is_infinite() && q.is_none()));
    }

    #[test]
    fn shadow_interpolates_and_stops_at_width() {
        // One contact pixel at the centre of a 41 x 1 strip.
        let w = 41;
        let depth = Image::filled(w, 1, 0.08);
        let nominal = Image::filled(w, 1, 0.09);
        let mut mask = Image::filled(w, 1, 0.0);
        *mask.get_mut(20, 0) = 1.0;
        let s = tactile_signature(&depth, &nominal, &mask, 10.0, (1.0, 1.0));
        assert_eq!(s.get(20, 0), 0.08);
        assert!((s.get(25, 0) - 0.085).abs() < 1e-7);
        assert!((s.get(15, 0) - 0.085).abs() < 1e-7);
        assert_eq!(s.get(30, 0), 0.09);
        assert_eq!(s.get(0, 0), 0.09);
    }
}
