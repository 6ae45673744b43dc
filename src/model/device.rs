//! Which candle device runs the model: `cpu` (default; our fast kernels), `cuda`, `cuda:N` or `metal` (candle's own
//! tensor ops, [`super::kernels::Kernels::Portable`]). GPU support is compiled in with the cargo features `cuda`
//! (needs the CUDA toolkit) or `metal` (macOS); a build without them says so instead of failing obscurely.

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

/// Open the device named `spec`.
pub fn open_device(spec: &str) -> Result<Device, ModelError> {
    let bad = |message: String| ModelError::Device {
        spec: spec.to_string(),
        message,
    };
    match parse(spec).map_err(bad)? {
        Spec::Cpu => Ok(Device::Cpu),
        Spec::Cuda(n) => Device::new_cuda(n).map_err(|e| {
            bad(format!(
                "{e} (GPU support is compiled in with `cargo build --release --features cuda`, which needs the \
                 CUDA toolkit)"
            ))
        }),
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
