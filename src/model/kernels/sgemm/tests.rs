//! Tests of the three GEMM patterns against a naive f64-accumulated reference, on both backends.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;

fn random(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-1.0f32..1.0)).collect()
}

/// One test per backend: the `gemm` crate everywhere, our AVX-512 kernels where the CPU that built the tests has
/// AVX-512F (elsewhere they are listed as ignored, with the reason; see build.rs).
macro_rules! on_both_backends {
    ($check:ident, $crate_test:ident, $avx512_test:ident) => {
        #[test]
        fn $crate_test() {
            $check(GemmBackend::GemmCrate);
        }

        #[test]
        #[cfg_attr(
            not(tnd_host_avx512),
            ignore = "this CPU has no AVX-512F: our AVX-512 kernels cannot run here"
        )]
        fn $avx512_test() {
            assert!(GemmBackend::Avx512.is_available());
            $check(GemmBackend::Avx512);
        }
    };
}

/// Asserts `got` (m × n at row stride `ldc`) equals `want` (dense m × n) within f32 rounding of sums of `k`
/// products of values in [-1, 1], and that the elements between rows (columns n..ldc) equal `before`'s.
fn check(
    got: &[f32],
    before: &[f32],
    want: &[f64],
    (m, n, k, ldc): (usize, usize, usize, usize),
    what: &str,
) {
    let tol = 2e-6 * (k as f64 + 8.0);
    for i in 0..m {
        for j in 0..n {
            let (g, w) = (got[i * ldc + j], want[i * n + j]);
            assert!(
                (f64::from(g) - w).abs() <= tol,
                "{what}: C[{i}, {j}] = {g}, want {w} (m {m}, n {n}, k {k})"
            );
        }
        if i + 1 < m {
            let gap = i * ldc + n..(i + 1) * ldc;
            assert_eq!(
                got[gap.clone()],
                before[gap],
                "{what}: wrote between rows after row {i}"
            );
        }
    }
}

/// Sizes (m, n, k) with tails: rows not a multiple of the 8-row register block, columns not a multiple of 16 or
/// 48, k beyond one K block (128), and small sizes (k = 0, 1; m, n < 8) that go to the gemm crate.
const SIZES: [(usize, usize, usize); 14] = [
    (1, 1, 1),
    (16, 113, 1152),
    (18, 227, 64),
    (7, 17, 1),
    (9, 48, 18),
    (13, 95, 129),
    (24, 33, 300),
    (64, 16, 7),
    (3, 50, 1030),
    (128, 64, 2049),
    (5, 6, 16),
    (10, 100, 0),
    (33, 8, 8),
    (8, 31, 9),
];

/// Runs `PackedA::matmul` for A given as `a[i·rs + p·cs]` and compares with the f64 reference, for
/// `accumulate` on and off, into a C with row stride `n + 5` pre-filled with random values.
fn run_nn(
    rng: &mut ChaCha8Rng,
    backend: GemmBackend,
    (m, n, k): (usize, usize, usize),
    transposed: bool,
) {
    let a = random(rng, m * k);
    let (rs, cs) = if transposed { (1, m) } else { (k, 1) };
    let (b, ldb) = (random(rng, k * (n + 3)), n + 3);
    let ldc = n + 5;
    let c0 = random(rng, m * ldc);
    let bias = random(rng, m);
    for init in [Init::Accumulate, Init::Zero, Init::RowBias(&bias)] {
        let mut want = vec![0f64; m * n];
        for i in 0..m {
            for j in 0..n {
                let start = match init {
                    Init::Accumulate => f64::from(c0[i * ldc + j]),
                    Init::Zero => 0.0,
                    Init::RowBias(bias) => f64::from(bias[i]),
                };
                want[i * n + j] = start
                    + (0..k)
                        .map(|p| f64::from(a[i * rs + p * cs]) * f64::from(b[p * ldb + j]))
                        .sum::<f64>();
            }
        }
        let pa = PackedA::with_backend(backend, m, k, &a, rs, cs).unwrap();
        let expected = if m.min(k) < SMALL_DIM {
            GemmBackend::GemmCrate
        } else {
            backend
        };
        assert_eq!(pa.backend(), expected);
        let mut c = c0.clone();
        pa.matmul(n, &b, ldb, &mut c, ldc, init).unwrap();
        let what = format!("{backend:?} nn transposed={transposed} {init:?}");
        check(&c, &c0, &want, (m, n, k, ldc), &what);
        // Same inputs, same bits (fixed summation order).
        let mut again = c0.clone();
        pa.matmul(n, &b, ldb, &mut again, ldc, init).unwrap();
        assert!(
            c.iter()
                .zip(&again)
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            "{what}: not deterministic"
        );
    }
}

// Pattern 1 (forward): `C += W · cols`, W row-major.
on_both_backends!(
    nn_matches_f64_reference,
    nn_matches_f64_reference_gemm_crate,
    nn_matches_f64_reference_avx512
);

fn nn_matches_f64_reference(backend: GemmBackend) {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    {
        for &size in &SIZES {
            run_nn(&mut rng, backend, size, false);
        }
    }
}

// Pattern 3 (input gradient): `dcols = Wᵀ · dY`, A read as the transpose of a row-major matrix.
on_both_backends!(
    nn_transposed_a_matches_f64_reference,
    nn_transposed_a_matches_f64_reference_gemm_crate,
    nn_transposed_a_matches_f64_reference_avx512
);

fn nn_transposed_a_matches_f64_reference(backend: GemmBackend) {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    {
        for &size in &SIZES {
            run_nn(&mut rng, backend, size, true);
        }
    }
}

// Pattern 2 (weight gradient): `dW (+)= dY · colsᵀ` with dY rows at a stride beyond k.
on_both_backends!(
    nt_matches_f64_reference,
    nt_matches_f64_reference_gemm_crate,
    nt_matches_f64_reference_avx512
);

fn nt_matches_f64_reference(backend: GemmBackend) {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    {
        for &(m, n, k) in &SIZES {
            let (a, lda) = (random(&mut rng, m * (k + 7)), k + 7);
            let (b, ldb) = (random(&mut rng, n * k), k);
            let ldc = n + 2;
            let c0 = random(&mut rng, m * ldc);
            for accumulate in [true, false] {
                let mut want = vec![0f64; m * n];
                for i in 0..m {
                    for j in 0..n {
                        let init = if accumulate {
                            f64::from(c0[i * ldc + j])
                        } else {
                            0.0
                        };
                        want[i * n + j] = init
                            + (0..k)
                                .map(|p| f64::from(a[i * lda + p]) * f64::from(b[j * ldb + p]))
                                .sum::<f64>();
                    }
                }
                let mut c = c0.clone();
                matmul_nt(
                    backend,
                    (m, n, k),
                    &a,
                    lda,
                    &b,
                    ldb,
                    &mut c,
                    ldc,
                    accumulate,
                )
                .unwrap();
                let what = format!("{backend:?} nt accumulate={accumulate}");
                check(&c, &c0, &want, (m, n, k, ldc), &what);
                let mut again = c0.clone();
                matmul_nt(
                    backend,
                    (m, n, k),
                    &a,
                    lda,
                    &b,
                    ldb,
                    &mut again,
                    ldc,
                    accumulate,
                )
                .unwrap();
                assert!(
                    c.iter()
                        .zip(&again)
                        .all(|(x, y)| x.to_bits() == y.to_bits()),
                    "{what}: not deterministic"
                );
            }
        }
    }
}

/// Buffers too small for the sizes are an error, not an out-of-bounds access.
#[test]
fn short_buffers_are_errors() {
    let a = vec![0f32; 12];
    assert!(PackedA::new(4, 4, &a, 4, 1).is_err());
    let pa = PackedA::new(3, 4, &a, 4, 1).unwrap();
    let mut c = vec![0f32; 3 * 5];
    assert!(pa.matmul(5, &[0f32; 19], 5, &mut c, 5, Init::Zero).is_err());
    assert!(pa
        .matmul(5, &[0f32; 20], 5, &mut c[..14], 5, Init::Zero)
        .is_err());
    assert!(pa
        .matmul(5, &[0f32; 20], 5, &mut c, 5, Init::RowBias(&[0.0; 2]))
        .is_err());
    assert!(pa.matmul(5, &[0f32; 20], 5, &mut c, 5, Init::Zero).is_ok());
    assert!(matmul_nt(
        GemmBackend::detect(),
        (3, 2, 4),
        &a,
        4,
        &[0f32; 7],
        4,
        &mut c,
        5,
        true
    )
    .is_err());
}

// Row-offset operands: a row reaching past the buffer, or a wrong number of offsets, is an error; a valid call
// equals the same product with the rows gathered into a strided matrix, on both backends.
on_both_backends!(
    offset_rows_match_gathered_rows_and_check_bounds,
    offset_rows_match_gathered_rows_and_check_bounds_gemm_crate,
    offset_rows_match_gathered_rows_and_check_bounds_avx512
);

fn offset_rows_match_gathered_rows_and_check_bounds(backend: GemmBackend) {
    let (m, k, n) = (9, 12, 37);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let a = random(&mut rng, m * k);
    let img = random(&mut rng, 200);
    // Overlapping, unordered rows as a convolution's taps are.
    let offs: Vec<usize> = (0..k).map(|p| (p * 13) % 150).collect();
    let gathered: Vec<f32> = offs.iter().flat_map(|&o| img[o..o + n].to_vec()).collect();
    {
        let pa = PackedA::with_backend(backend, m, k, &a, k, 1).unwrap();
        let mut want = vec![0f32; m * n];
        pa.matmul(n, &gathered, n, &mut want, n, Init::Zero)
            .unwrap();
        let mut got = vec![0f32; m * n];
        // SAFETY: got holds m rows of n floats.
        unsafe { pa.matmul_offsets_raw(n, &img, &offs, got.as_mut_ptr(), n, Init::Zero) }.unwrap();
        let err = want
            .iter()
            .zip(&got)
            .map(|(x, y)| (x - y).abs())
            .fold(0f32, f32::max);
        assert!(err < 1e-5, "{backend:?}: {err}");
        // Aᵀ-side offsets: C[k, m] = rows(img)[k, n] · A'[m, n]ᵀ against the gathered rows.
        let b = random(&mut rng, m * n);
        let mut want = vec![0f32; k * m];
        matmul_nt(backend, (k, m, n), &gathered, n, &b, n, &mut want, m, false).unwrap();
        let mut got = vec![0f32; k * m];
        matmul_nt_offsets(backend, (k, m, n), &img, &offs, &b, n, &mut got, m, false).unwrap();
        let err = want
            .iter()
            .zip(&got)
            .map(|(x, y)| (x - y).abs())
            .fold(0f32, f32::max);
        assert!(err < 1e-5, "nt {backend:?}: {err}");
        // Out of bounds and miscounted offsets.
        let mut c = vec![0f32; m * n];
        let short = &img[..offs.iter().max().unwrap() + n - 1];
        // SAFETY: c holds m rows of n floats.
        assert!(
            unsafe { pa.matmul_offsets_raw(n, short, &offs, c.as_mut_ptr(), n, Init::Zero) }
                .is_err()
        );
        assert!(unsafe {
            pa.matmul_offsets_raw(n, &img, &offs[1..], c.as_mut_ptr(), n, Init::Zero)
        }
        .is_err());
        assert!(
            matmul_nt_offsets(backend, (k, m, n), short, &offs, &b, n, &mut got, m, false).is_err()
        );
    }
}

// A product computed in row ranges (as threads split a convolution's output channels) gives the whole product's
// bits, bias included; a range not starting on a panel boundary, or past A's rows, is an error.
on_both_backends!(
    row_ranges_give_the_whole_product,
    row_ranges_give_the_whole_product_gemm_crate,
    row_ranges_give_the_whole_product_avx512
);

fn row_ranges_give_the_whole_product(backend: GemmBackend) {
    let (m, k, n) = (37, 20, 53);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let a = random(&mut rng, m * k);
    let bias = random(&mut rng, m);
    let img = random(&mut rng, 300);
    let offs: Vec<usize> = (0..k).map(|p| (p * 11) % 240).collect();
    let pa = PackedA::with_backend(backend, m, k, &a, k, 1).unwrap();
    let mut want = vec![0f32; m * n];
    // SAFETY: want holds m rows of n floats.
    unsafe { pa.matmul_offsets_raw(n, &img, &offs, want.as_mut_ptr(), n, Init::RowBias(&bias)) }
        .unwrap();
    let align = pa.row_align();
    let mut got = vec![0f32; m * n];
    let cuts = [0, 2 * align, 3 * align, m];
    for r in cuts.windows(2) {
        // SAFETY: rows r[0]..r[1] of got, n floats each.
        unsafe {
            pa.matmul_offsets_rows_raw(
                r[0]..r[1],
                n,
                &img,
                &offs,
                got.as_mut_ptr().add(r[0] * n),
                n,
                Init::RowBias(&bias),
            )
        }
        .unwrap();
    }
    assert_eq!(got, want, "{backend:?}");
    let mut c = vec![0f32; m * n];
    // SAFETY: c holds m rows of n floats; the calls are refused before writing.
    unsafe {
        assert!(pa
            .matmul_offsets_rows_raw(30..m + 1, n, &img, &offs, c.as_mut_ptr(), n, Init::Zero)
            .is_err());
        if align > 1 {
            assert!(pa
                .matmul_offsets_rows_raw(3..9, n, &img, &offs, c.as_mut_ptr(), n, Init::Zero)
                .is_err());
        }
    }
}

// The image product (a convolution writing its output directly) gives the wide product's bits at every on-image
// grid position, for every init, K across several blocks, m off the panel height, a row range, and leaves C's
// elements past each row's image untouched; widths the backend cannot take are errors.
on_both_backends!(
    image_product_is_the_wide_product_on_the_image,
    image_product_is_the_wide_product_on_the_image_gemm_crate,
    image_product_is_the_wide_product_on_the_image_avx512
);

fn image_product_is_the_wide_product_on_the_image(backend: GemmBackend) {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let (m, k) = (21, 300);
    let a = random(&mut rng, m * k);
    let bias = random(&mut rng, m);
    let pa = PackedA::with_backend(backend, m, k, &a, k, 1).unwrap();
    let align = pa.row_align();
    let widths: &[usize] = if backend == GemmBackend::Avx512 {
        &[16, 32, 48, 64]
    } else {
        &[8, 16, 37]
    };
    for &w in widths {
        for rows in [1, 3, 4] {
            let wp = w + 2;
            let n = rows * wp;
            let img = random(&mut rng, 4 * n + 64);
            let offs: Vec<usize> = (0..k).map(|p| (p * 7) % (3 * n)).collect();
            let init_c = random(&mut rng, m * n);
            for init in [Init::Zero, Init::RowBias(&bias), Init::Accumulate] {
                let mut wide = init_c.clone();
                // SAFETY: wide holds m rows of n floats.
                unsafe { pa.matmul_offsets_raw(n, &img, &offs, wide.as_mut_ptr(), n, init) }
                    .unwrap();
                // C at stride ldc > rows · w: the gap must stay as it was. Accumulate starts from the same
                // values as the wide product did at those positions.
                let ldc = rows * w + 5;
                let mut got = vec![f32::NAN; m * ldc];
                for i in 0..m {
                    for y in 0..rows {
                        for x in 0..w {
                            got[i * ldc + y * w + x] = init_c[i * n + y * wp + x];
                        }
                    }
                }
                let cuts = [0, align, m];
                for r in cuts.windows(2) {
                    // SAFETY: rows r[0]..r[1] of got at stride ldc, rows · w floats each.
                    unsafe {
                        pa.matmul_offsets_image_raw(
                            r[0]..r[1],
                            (rows, w, wp),
                            &img,
                            &offs,
                            got.as_mut_ptr().add(r[0] * ldc),
                            ldc,
                            init,
                        )
                    }
                    .unwrap();
                }
                for i in 0..m {
                    for y in 0..rows {
                        for x in 0..w {
                            assert_eq!(
                                got[i * ldc + y * w + x].to_bits(),
                                wide[i * n + y * wp + x].to_bits(),
                                "{backend:?} w {w} rows {rows} at ({i}, {y}, {x})"
                            );
                        }
                    }
                    assert!(got[i * ldc + rows * w..(i + 1) * ldc]
                        .iter()
                        .all(|v| v.is_nan()));
                }
            }
        }
    }
    let img = random(&mut rng, 4000);
    let offs: Vec<usize> = (0..k).map(|p| p % 100).collect();
    let mut c = vec![0f32; m * 64];
    // SAFETY: c holds m rows of 64 floats; the calls are refused before writing.
    unsafe {
        assert!(pa
            .matmul_offsets_image_raw(
                0..m,
                (2, 34, 32),
                &img,
                &offs,
                c.as_mut_ptr(),
                64,
                Init::Zero
            )
            .is_err());
        if backend == GemmBackend::Avx512 {
            assert!(pa
                .matmul_offsets_image_raw(
                    0..m,
                    (2, 24, 26),
                    &img,
                    &offs,
                    c.as_mut_ptr(),
                    64,
                    Init::Zero
                )
                .is_err());
        }
        let short = &img[..99 + 2 * 34 - 1];
        assert!(pa
            .matmul_offsets_image_raw(
                0..m,
                (2, 32, 34),
                short,
                &offs,
                c.as_mut_ptr(),
                64,
                Init::Zero
            )
            .is_err());
    }
}
