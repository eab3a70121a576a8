//! Where the networks train: `--device cpu|cuda[:N]`. The CPU runs the exact fused path
//! ([`crate::numeric`]); a CUDA device runs the device-generic path (`agents::common::device`),
//! which needs a build with the `cuda` feature (`scripts/build-cuda.sh`).
use std::fmt;
use std::str::FromStr;

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

/// A compute device as the command line names it (and as files write it: `cpu`, `cuda:0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum ComputeDevice {
    /// The CPU, with the exact fused kernels.
    #[default]
    Cpu,
    /// CUDA device N, through candle's CUDA backend.
    Cuda(usize),
}

impl FromStr for ComputeDevice {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<ComputeDevice> {
        match s {
            "cpu" => Ok(ComputeDevice::Cpu),
            "cuda" => Ok(ComputeDevice::Cuda(0)),
            _ => match s.strip_prefix("cuda:").map(str::parse::<usize>) {
                Some(Ok(i)) => Ok(ComputeDevice::Cuda(i)),
                _ => bail!("unknown device '{s}': expected cpu, cuda or cuda:N (N a GPU index, 0 first)"),
            },
        }
    }
}

impl TryFrom<String> for ComputeDevice {
    type Error = anyhow::Error;

    fn try_from(s: String) -> Result<ComputeDevice> {
        s.parse()
    }
}

impl From<ComputeDevice> for String {
    fn from(d: ComputeDevice) -> String {
        d.to_string()
    }
}

impl fmt::Display for ComputeDevice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ComputeDevice::Cpu => write!(f, "cpu"),
            ComputeDevice::Cuda(i) => write!(f, "cuda:{i}"),
        }
    }
}

impl ComputeDevice {
    /// Whether this build can use CUDA devices at all.
    pub const CUDA_BUILT: bool = cfg!(feature = "cuda");

    /// The candle device, or a clear error: a build without the `cuda` feature, or no such GPU.
    pub fn open(self) -> Result<candle_core::Device> {
        match self {
            ComputeDevice::Cpu => Ok(candle_core::Device::Cpu),
            ComputeDevice::Cuda(i) => open_cuda(i),
        }
    }
}

#[cfg(feature = "cuda")]
fn open_cuda(index: usize) -> Result<candle_core::Device> {
    candle_core::Device::new_cuda(index).map_err(|e| {
        anyhow::anyhow!(
            "--device cuda:{index}: no usable CUDA device {index} ({e}). `nvidia-smi -L` lists this machine's GPUs; \
             the driver's libcuda.so.1 and CUDA 13's libcublas, libcurand and libnvrtc must be on the library path \
             (docs/gpu.md)"
        )
    })
}

#[cfg(not(feature = "cuda"))]
fn open_cuda(index: usize) -> Result<candle_core::Device> {
    bail!(
        "--device cuda:{index}: this locobench was built without the `cuda` feature. Build it with \
         scripts/build-cuda.sh (docs/gpu.md), or train with --device cpu"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_prints_devices() {
        for (text, device) in
            [("cpu", ComputeDevice::Cpu), ("cuda", ComputeDevice::Cuda(0)), ("cuda:3", ComputeDevice::Cuda(3))]
        {
            assert_eq!(text.parse::<ComputeDevice>().unwrap(), device);
        }
        assert_eq!(ComputeDevice::Cuda(2).to_string(), "cuda:2");
        #[derive(Serialize, Deserialize)]
        struct File {
            device: ComputeDevice,
        }
        let text = toml::to_string(&File { device: ComputeDevice::Cuda(1) }).unwrap();
        assert_eq!(text.trim(), "device = \"cuda:1\"");
        assert_eq!(toml::from_str::<File>(&text).unwrap().device, ComputeDevice::Cuda(1));
        for bad in ["gpu", "cuda:", "cuda:x", "cuda:-1", "CPU"] {
            let err = bad.parse::<ComputeDevice>().unwrap_err().to_string();
            assert!(err.contains(&format!("'{bad}'")) && err.contains("cpu, cuda or cuda:N"), "{err}");
        }
    }

    #[cfg(not(feature = "cuda"))]
    #[test]
    fn cuda_without_the_feature_is_a_clear_error() {
        let err = ComputeDevice::Cuda(0).open().unwrap_err().to_string();
        assert!(err.contains("without the `cuda` feature") && err.contains("scripts/build-cuda.sh"), "{err}");
        assert!(ComputeDevice::Cpu.open().unwrap().is_cpu());
    }
}
