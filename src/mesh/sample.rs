//! Points on a mesh's surface: uniform by area and reproducible from a seed (Chamfer distances, shape checks).

use glam::{DVec3, Vec3};

use super::Mesh;

/// Sample `n` points uniformly (by area) on the surface of `mesh`, reproducibly from `seed` (for Chamfer distances).
pub fn sample_surface(mesh: &Mesh, n: usize, seed: u64) -> Vec<DVec3> {
    use rand::{Rng, SeedableRng};
    let areas: Vec<f64> = (0..mesh.triangles().len())
        .map(|i| {
            let [a, b, c] = mesh.triangle(i);
            f64::from((b - a).cross(c - a).length()) * 0.5
        })
        .collect();
    let mut cumulative = Vec::with_capacity(areas.len());
    let mut total = 0.0;
    for a in &areas {
        total += a;
        cumulative.push(total);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let x = rng.random::<f64>() * total;
            let i = cumulative.partition_point(|&c| c < x).min(areas.len() - 1);
            let [a, b, c] = mesh.triangle(i).map(Vec3::as_dvec3);
            let (mut r1, mut r2) = (rng.random::<f64>(), rng.random::<f64>());
            if r1 + r2 > 1.0 {
                (r1, r2) = (1.0 - r1, 1.0 - r2);
            }
            a + (b - a) * r1 + (c - a) * r2
        })
        .collect()
}
