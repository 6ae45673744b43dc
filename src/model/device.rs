//! Which candle device runs the model: `cpu` (default; our fast kernels), `cuda`, `cuda:N` or `metal` (candle's own
//! tensor ops, [`super::kernels::Kernels::Portable`]). GPU support is compiled in with the cargo features `cuda`
//! (needs the CUDA toolkit to build; assets/models/gpu/build_cuda.sh) or `metal` (macOS); a build without them says
//! so, and a CUDA build names the CUDA libraries it cannot load, instead of failing obscurely.

use candle_core::Device;

use super::ModelError;

/// Check the syntax of a device name without opening the device.
pub fn check_device_name(spec: &str) -> Result<(), crate::error::InvalidSetting> {
    parse(spec)
        .map(|_| ())
        .map_err(|m| crate::error::InvalidSetting::new("device", m))
}

enum Spec {
    Cpu,
    Cuda(usize),
    Metal(usize),
}

fn parse(spec: &str) -> Result<Spec, String> {
    let s = spec.trim().to_ascii_lowercase();
    let ordinal = |rest: &str| -> Result<usize, String> {
        match rest.strip_prefix(':') {
            None if rest.is_empty() => Ok(0),
            Some(n) => n
                .parse()
                .map_err(|_| format!("device '{spec}': '{n}' is not a device number")),
            None => Err(format!("device '{spec}': use cpu, cuda, cuda:N or metal")),
        }
    };
    if s == "cpu" {
        Ok(Spec::Cpu)
    } else if let Some(rest) = s.strip_prefix("cuda") {
        Ok(Spec::Cuda(ordinal(rest)?))
    } else if let Some(rest) = s.strip_prefix("metal") {
        Ok(Spec::Metal(ordinal(rest)?))
    } else {
        Err(format!("device '{spec}': use cpu, cuda, cuda:N or metal"))
    }
}

/// The CUDA libraries candle loads when it opens a CUDA device (cudarc's `dynamic-loading`) that cannot be loaded
/// here: cudarc panics on the first call into a missing one, so they are looked for first.
#[cfg(feature = "cuda")]
fn missing_cuda_libraries() -> Vec<&'static str> {
    use candle_core::cuda_backend::cudarc;
    // SAFETY: each call only tries to open a shared library by its names (libloading), which cudarc does anyway
    // when the device is opened; loading runs the library's initialisers, as that would.
    let present = unsafe {
        [
            (
                "libcuda (the NVIDIA driver)",
                cudarc::driver::sys::is_culib_present(),
            ),
            ("libcublas", cudarc::cublas::sys::is_culib_present()),
            ("libcublasLt", cudarc::cublaslt::sys::is_culib_present()),
            ("libcurand", cudarc::curand::sys::is_culib_present()),
            ("libnvrtc", cudarc::nvrtc::sys::is_culib_present()),
        ]
    };
    present
        .into_iter()
        .filter(|(_, ok)| !ok)
        .map(|(name, _)| name)
        .collect()
}

/// Without the `cuda` feature there is nothing to load: `Device::new_cuda` says how to build with it.
#[cfg(not(feature = "cuda"))]
fn missing_cuda_libraries() -> Vec<&'static str> {
    Vec::new()
}

/// Open the device named `spec`.
pub fn open_device(spec: &str) -> Result<Device, ModelError> {
    let bad = |message: String| ModelError::Device {
        spec: spec.to_string(),
        message,
    };
    match parse(spec).map_err(bad)? {
        Spec::Cpu => Ok(Device::Cpu),
        Spec::Cuda(n) => {
            let missing = missing_cuda_libraries();
            if !missing.is_empty() {
                return Err(bad(format!(
                    "cannot load {} (CUDA 13; put their folder on LD_LIBRARY_PATH)",
                    missing.join(", ")
                )));
            }
            Device::new_cuda(n).map_err(|e| {
                bad(format!(
                    "{e} (GPU support is compiled in with `cargo build --release --features cuda`, or \
                     assets/models/gpu/build_cuda.sh)"
                ))
            })
        }
        Spec::Metal(n) => Device::new_metal(n).map_err(|e| {
            bad(format!(
                "{e} (Metal support is compiled in with `cargo build --release --features metal`, on macOS)"
            ))
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_a_cpu_only_build_says_how_to_get_a_gpu() {
        assert!(open_device("cpu").unwrap().is_cpu());
        assert!(open_device(" CPU ").unwrap().is_cpu());
        for ok in ["cuda", "cuda:1", "metal", "metal:0"] {
            assert!(check_device_name(ok).is_ok(), "{ok}");
        }
        for bad in ["gpu", "cuda:x", "cuda1", ""] {
            assert!(check_device_name(bad).is_err(), "{bad}");
        }
        #[cfg(not(feature = "cuda"))]
        {
            let err = open_device("cuda").unwrap_err().to_string();
            assert!(err.contains("--features cuda"), "{err}");
        }
    }
}
