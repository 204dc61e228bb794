//! Where the network runs: Burn's flex backend on the CPU, or a GPU through wgpu when mvpcc is
//! built with `--features wgpu`. Asking for a GPU never fails: without one (or with only a
//! software rasterizer, which is tens of times slower than flex) the CPU is used and the
//! returned notice says why.

use burn::tensor::Device;
use clap::ValueEnum;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DeviceChoice {
    Cpu,
    Gpu,
}

/// An opened device and a one-line description of it for the log.
pub struct Opened {
    pub device: Device,
    pub description: String,
    /// Why a GPU was asked for and the CPU is used instead.
    pub fallback: Option<String>,
}

pub fn open(choice: DeviceChoice) -> Opened {
    let cpu = |fallback| Opened {
        device: Device::flex(),
        description: format!("CPU (flex, {} threads)", rayon::current_num_threads()),
        fallback,
    };
    match choice {
        DeviceChoice::Cpu => cpu(None),
        DeviceChoice::Gpu => match open_gpu() {
            Ok((device, name)) => Opened {
                device,
                description: format!("GPU ({name}, wgpu)"),
                fallback: None,
            },
            Err(why) => cpu(Some(format!("{why}; running on the CPU"))),
        },
    }
}

#[cfg(feature = "wgpu")]
fn open_gpu() -> Result<(Device, String), String> {
    let device = Device::wgpu_options()
        .init()
        .map_err(|e| format!("no usable GPU adapter ({e})"))?;
    let identity = device.identity();
    let name = identity
        .as_ref()
        .map_or_else(|| "unnamed adapter".to_string(), |i| i.name.clone());
    if is_software_adapter(&name, identity.is_some_and(|i| i.physical.is_none())) {
        return Err(format!(
            "the only GPU adapter is the software rasterizer {name}"
        ));
    }
    Ok((device, name))
}

#[cfg(not(feature = "wgpu"))]
fn open_gpu() -> Result<(Device, String), String> {
    Err("this mvpcc was built without GPU support (cargo feature `wgpu`)".to_string())
}

/// llvmpipe, lavapipe and SwiftShader present themselves as GPUs but run on the CPU.
#[cfg_attr(not(feature = "wgpu"), allow(dead_code))]
fn is_software_adapter(name: &str, no_physical_card: bool) -> bool {
    let name = name.to_ascii_lowercase();
    no_physical_card
        || ["llvmpipe", "lavapipe", "swiftshader", "software"]
            .iter()
            .any(|s| name.contains(s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asking_for_a_gpu_always_yields_a_device() {
        let opened = open(DeviceChoice::Gpu);
        if opened.fallback.is_some() {
            assert!(opened.description.starts_with("CPU"));
        }
        let x = burn::tensor::Tensor::<1>::ones([3], &opened.device).sum();
        assert_eq!(x.into_data().try_into_vec::<f32>().unwrap(), vec![3.0]);
    }

    #[test]
    fn software_rasterizers_are_recognized() {
        assert!(is_software_adapter(
            "llvmpipe (LLVM 15.0.6, 256 bits)",
            false
        ));
        assert!(is_software_adapter("Lavapipe", false));
        assert!(is_software_adapter("SwiftShader Device (Subzero)", false));
        assert!(is_software_adapter("Some GPU", true));
        assert!(!is_software_adapter("NVIDIA H100 80GB HBM3", false));
    }
}
