//! Build script: tells the tests whether the machine building them (which runs them) has AVX-512F, so the tests of our
//! AVX-512 kernels show as "ignored: this CPU has no AVX-512F" there instead of passing without running.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(tnd_host_avx512)");
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f") {
        println!("cargo::rustc-cfg=tnd_host_avx512");
    }
}
