//! Where the network runs: Burn's flex backend on the CPU, CUDA when mvpcc is built with
//! `--features cuda`, or any GPU through wgpu with `--features wgpu`. `--device gpu` never
//! fails: it takes CUDA when the build has it and a CUDA device answers, else wgpu, else the
//! CPU, and the returned notice says why. `--device cuda|wgpu` is an explicit pick and fails with
//! one line when that backend cannot run here.

use burn::tensor::Device;
use clap::ValueEnum;
use thiserror::Error;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DeviceChoice {
    /// The CPU, on every core.
    Cpu,
    /// The fastest GPU backend that answers (CUDA, then wgpu), else the CPU with a warning.
    Gpu,
    /// An NVIDIA GPU through CUDA (a build with the `cuda` feature), else an error.
    Cuda,
    /// A GPU through wgpu: Vulkan, Metal or DirectX 12 (a build with the `wgpu` feature), else an
    /// error.
    Wgpu,
}

/// An opened device and a one-line description of it for the log.
pub struct Opened {
    pub device: Device,
    pub description: String,
    pub backend: Backend,
    /// Why a GPU was asked for and the CPU is used instead.
    pub fallback: Option<String>,
}

/// The backend an [`Opened`] device runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    Cpu,
    Cuda,
    Wgpu,
}

#[derive(Debug, Error)]
#[error("--device {backend}: {why}")]
pub struct DeviceError {
    backend: &'static str,
    why: Unavailable,
}

/// Why a GPU backend cannot run here.
#[derive(Debug)]
enum Unavailable {
    #[cfg_attr(all(feature = "cuda", feature = "wgpu"), allow(dead_code))]
    NotBuilt { backend: &'static str },
    #[cfg_attr(not(any(feature = "cuda", feature = "wgpu")), allow(dead_code))]
    NoDevice(String),
}

impl std::fmt::Display for Unavailable {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self {
            Unavailable::NotBuilt { backend } => {
                write!(f, "this mvpcc was built without {}", built(backend))
            }
            Unavailable::NoDevice(why) => f.write_str(why),
        }
    }
}

/// "CUDA (cargo feature `cuda`)": how a missing backend is named.
fn built(backend: &str) -> String {
    format!(
        "{backend} (cargo feature `{}`)",
        backend.to_ascii_lowercase()
    )
}

pub fn open(choice: DeviceChoice) -> Result<Opened, DeviceError> {
    let explicit = |kind, name, opened: Result<(Device, String), Unavailable>| {
        opened
            .map(|opened| found(opened, kind))
            .map_err(|why| DeviceError { backend: name, why })
    };
    match choice {
        DeviceChoice::Cpu => Ok(cpu(None)),
        DeviceChoice::Cuda => explicit(Backend::Cuda, "cuda", open_cuda()),
        DeviceChoice::Wgpu => explicit(Backend::Wgpu, "wgpu", open_wgpu(true)),
        DeviceChoice::Gpu => Ok(open_any_gpu()),
    }
}

fn found((device, description): (Device, String), backend: Backend) -> Opened {
    Opened {
        device,
        description,
        backend,
        fallback: None,
    }
}

fn cpu(fallback: Option<String>) -> Opened {
    Opened {
        device: Device::flex(),
        description: format!("CPU (flex, {} threads)", rayon::current_num_threads()),
        backend: Backend::Cpu,
        fallback,
    }
}

fn open_any_gpu() -> Opened {
    open_cuda()
        .map(|opened| found(opened, Backend::Cuda))
        .or_else(|cuda| {
            open_wgpu(false)
                .map(|opened| found(opened, Backend::Wgpu))
                .map_err(|wgpu| format!("{}; running on the CPU", both(&cuda, &wgpu)))
        })
        .unwrap_or_else(|why| cpu(Some(why)))
}

/// `--devices LIST` refused before any work.
#[derive(Debug, Error)]
#[error("--devices {list}: {problem}")]
pub struct DeviceListError {
    list: String,
    problem: String,
}

/// The devices of a data-parallel run (`mvpcc train --devices`), the first of which keeps the
/// weights: `cpu` (as often as wanted: replicas that share the cores, for tests), `cuda:N`
/// (`cuda` is `cuda:0`), or `all` for every CUDA device. Each is asked for a tiny result, so
/// that a device that does not answer is refused here rather than in the first step.
pub fn open_list(list: &str) -> Result<Vec<Opened>, DeviceListError> {
    let refuse = |problem: String| DeviceListError {
        list: list.to_string(),
        problem,
    };
    let entries: Vec<&str> = list.split(',').map(str::trim).collect();
    // Read whole before any device is opened, so that a mistyped list costs nothing.
    let mut cuda_seen = Vec::new();
    for entry in &entries {
        match *entry {
            "cpu" => {}
            "all" if entries.len() == 1 => {}
            "all" => return Err(refuse("`all` stands alone".to_string())),
            "wgpu" => {
                return Err(refuse(
                    "wgpu trains on one device (--device wgpu); several need CUDA".to_string(),
                ))
            }
            _ => {
                let index = cuda_index(entry).ok_or_else(|| {
                    refuse(format!(
                        "`{entry}` is not a device (cpu, cuda, cuda:N or all)"
                    ))
                })?;
                if cuda_seen.contains(&index) {
                    return Err(refuse(format!(
                        "cuda:{index} is listed twice; a GPU runs one replica"
                    )));
                }
                cuda_seen.push(index);
            }
        }
    }
    if entries.contains(&"cpu") && !cuda_seen.is_empty() {
        return Err(refuse(
            "mixes the CPU and GPUs; the replicas run on one backend".to_string(),
        ));
    }
    let opened = match entries[..] {
        ["all"] => all_cuda().map_err(|why| refuse(why.to_string()))?,
        _ => entries
            .iter()
            .map(|entry| match cuda_index(entry) {
                Some(index) => nth_cuda(index).map_err(|why| refuse(why.to_string())),
                None => Ok(cpu(None)),
            })
            .collect::<Result<Vec<_>, _>>()?,
    };
    for (k, o) in opened.iter().enumerate() {
        answers(&o.device).map_err(|why| {
            refuse(format!(
                "device {} ({}) does not answer: {why}",
                k + 1,
                o.description
            ))
        })?;
    }
    Ok(opened)
}

/// `cuda` or `cuda:N` → N.
fn cuda_index(entry: &str) -> Option<usize> {
    match entry.strip_prefix("cuda")? {
        "" => Some(0),
        rest => rest.strip_prefix(':')?.parse().ok(),
    }
}

/// A tiny computation on `device`, its panic (a lost or broken device) as the error.
fn answers(device: &Device) -> Result<(), String> {
    let sum = crate::core::guard::guarded(|| {
        burn::tensor::Tensor::<1>::ones([2], device)
            .sum()
            .into_scalar::<f32>()
    })?;
    match sum == 2.0 {
        true => Ok(()),
        false => Err(format!("1 + 1 came back as {sum}")),
    }
}

#[cfg(feature = "cuda")]
fn cuda_devices() -> Vec<Device> {
    Device::enumerate(burn::tensor::DeviceType::Cuda).into_vec()
}

/// CUDA device `index`, named with its index as a list has several alike.
#[cfg(feature = "cuda")]
fn cuda_opened(index: usize, device: Device) -> Opened {
    let name = device
        .identity()
        .map_or_else(|| "unnamed CUDA device".to_string(), |i| i.name);
    found((device, format!("cuda:{index} ({name})")), Backend::Cuda)
}

#[cfg(feature = "cuda")]
fn all_cuda() -> Result<Vec<Opened>, Unavailable> {
    let devices = cuda_devices();
    if devices.is_empty() {
        return Err(Unavailable::NoDevice("no CUDA device answers".to_string()));
    }
    Ok(devices
        .into_iter()
        .enumerate()
        .map(|(k, d)| cuda_opened(k, d))
        .collect())
}

#[cfg(feature = "cuda")]
fn nth_cuda(index: usize) -> Result<Opened, Unavailable> {
    let devices = cuda_devices();
    let count = devices.len();
    devices
        .into_iter()
        .nth(index)
        .map(|d| cuda_opened(index, d))
        .ok_or_else(|| {
            Unavailable::NoDevice(format!(
                "there is no cuda:{index} ({count} CUDA device{} here)",
                if count == 1 { "" } else { "s" }
            ))
        })
}

#[cfg(not(feature = "cuda"))]
fn all_cuda() -> Result<Vec<Opened>, Unavailable> {
    Err(Unavailable::NotBuilt { backend: "CUDA" })
}

#[cfg(not(feature = "cuda"))]
fn nth_cuda(_index: usize) -> Result<Opened, Unavailable> {
    Err(Unavailable::NotBuilt { backend: "CUDA" })
}

/// The backends this build can run the network on, as `mvpcc --version` lists them.
pub fn built_backends() -> Vec<&'static str> {
    let mut backends = vec!["CPU (flex)"];
    if cfg!(feature = "cuda") {
        backends.push("CUDA");
    }
    if cfg!(feature = "wgpu") {
        backends.push("wgpu");
    }
    backends
}

/// Two backends the build lacks are said in one clause, not two alike.
fn both(cuda: &Unavailable, wgpu: &Unavailable) -> String {
    match (cuda, wgpu) {
        (Unavailable::NotBuilt { backend: a }, Unavailable::NotBuilt { backend: b }) => {
            format!("this mvpcc was built without {} or {}", built(a), built(b))
        }
        _ => format!("{cuda}; {wgpu}"),
    }
}

#[cfg(feature = "cuda")]
fn open_cuda() -> Result<(Device, String), Unavailable> {
    use burn::tensor::DeviceType;
    let device = Device::enumerate(DeviceType::Cuda)
        .into_vec()
        .into_iter()
        .next()
        .ok_or_else(|| {
            Unavailable::NoDevice("no CUDA device answers (no NVIDIA driver or no GPU)".to_string())
        })?;
    let name = device
        .identity()
        .map_or_else(|| "unnamed CUDA device".to_string(), |i| i.name);
    Ok((device, format!("GPU ({name}, CUDA)")))
}

#[cfg(not(feature = "cuda"))]
fn open_cuda() -> Result<(Device, String), Unavailable> {
    Err(Unavailable::NotBuilt { backend: "CUDA" })
}

/// The wgpu adapter. A software one (lavapipe, llvmpipe) is taken only when `software` allows
/// it: `--device wgpu` names the backend and gets it, however slow; `--device gpu` wants speed.
#[cfg(feature = "wgpu")]
fn open_wgpu(software: bool) -> Result<(Device, String), Unavailable> {
    let device = Device::wgpu_options()
        .init()
        .map_err(|e| Unavailable::NoDevice(format!("no usable wgpu adapter ({e})")))?;
    let identity = device.identity();
    let name = identity
        .as_ref()
        .map_or_else(|| "unnamed adapter".to_string(), |i| i.name.clone());
    if is_software_adapter(&name, identity.is_some_and(|i| i.physical.is_none())) {
        if !software {
            return Err(Unavailable::NoDevice(format!(
                "the only wgpu adapter is the software rasterizer {name}"
            )));
        }
        return Ok((device, format!("{name} (software Vulkan on the CPU, wgpu)")));
    }
    Ok((device, format!("GPU ({name}, wgpu)")))
}

#[cfg(not(feature = "wgpu"))]
fn open_wgpu(_software: bool) -> Result<(Device, String), Unavailable> {
    Err(Unavailable::NotBuilt { backend: "wgpu" })
}

/// Whether tensors on `device` run on flex, Burn's CPU backend: layers pick their CPU or GPU
/// formulation by this (see [`crate::model`]'s layers), so weights stay device-independent.
pub fn is_cpu(device: &Device) -> bool {
    // Device equality ignores autodiff.
    *device == Device::flex()
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
        let opened = open(DeviceChoice::Gpu).unwrap();
        if opened.fallback.is_some() {
            assert!(opened.description.starts_with("CPU"));
            assert!(is_cpu(&opened.device));
        }
        let x = burn::tensor::Tensor::<1>::ones([3], &opened.device).sum();
        assert_eq!(x.into_data().try_into_vec::<f32>().unwrap(), vec![3.0]);
    }

    #[cfg(not(feature = "cuda"))]
    #[test]
    fn an_explicit_backend_the_build_lacks_is_an_error_naming_it() {
        let e = open(DeviceChoice::Cuda).err().unwrap().to_string();
        assert!(e.starts_with("--device cuda: "), "{e}");
        assert!(e.contains("feature `cuda`"), "{e}");
    }

    #[test]
    fn device_lists_open_or_are_refused_in_one_line_naming_the_problem() {
        let two = open_list("cpu, cpu").unwrap();
        assert_eq!(two.len(), 2);
        assert!(two.iter().all(|o| is_cpu(&o.device)));
        for (list, problem) in [
            ("cpu,gpu0", "`gpu0` is not a device"),
            ("cpu,", "`` is not a device"),
            ("all,cpu", "`all` stands alone"),
            ("wgpu", "wgpu trains on one device"),
            ("cuda:x", "`cuda:x` is not a device"),
            ("cuda:1,cuda:1", "cuda:1 is listed twice"),
            ("cpu,cuda:0", "mixes the CPU and GPUs"),
        ] {
            let e = open_list(list).err().unwrap().to_string();
            assert_eq!(
                e,
                format!("--devices {list}: {}", e.split_once(": ").unwrap().1)
            );
            assert!(e.contains(problem), "{list}: {e}");
        }
        assert_eq!(cuda_index("cuda"), Some(0));
        assert_eq!(cuda_index("cuda:3"), Some(3));
        assert_eq!(cuda_index("cudax"), None);
    }

    #[cfg(not(feature = "cuda"))]
    #[test]
    fn a_gpu_list_without_cuda_says_the_build_lacks_it() {
        for list in ["cuda:0,cuda:1", "all"] {
            let e = open_list(list).err().unwrap().to_string();
            assert!(e.contains("feature `cuda`"), "{e}");
        }
    }

    #[test]
    fn the_cpu_is_recognized_with_and_without_autodiff() {
        assert!(is_cpu(&Device::flex()));
        assert!(is_cpu(&Device::flex().autodiff()));
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
