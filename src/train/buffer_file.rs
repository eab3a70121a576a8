//! A checkpoint's `buffer.safetensors`: the replay buffer as named flat tensors (`meta` =
//! capacity, obs_dim, act_dim, write, len as i64; `obs`, `actions`, `rewards`, `side_values`,
//! `newest_next` as f32; `flags` as u8; `side_index` as i64).
//!
//! Written straight from the buffer's own storage and read into arrays the restored buffer takes
//! over, so that saving or loading a full 1M-transition buffer costs about one buffer's worth of
//! memory on top of the buffer, not three (`cargo bench --bench memory` measures a run's peak).
use std::borrow::Cow;
use std::path::Path;

use anyhow::{Context, Result};
use safetensors::{Dtype, SafeTensors, View};

use crate::agents::common::buffer::{BufferSnapshot, ReplayBuffer};

/// One named tensor's bytes, borrowed where they can be.
struct Column<'a> {
    dtype: Dtype,
    shape: [usize; 1],
    bytes: Cow<'a, [u8]>,
}

impl View for &Column<'_> {
    fn dtype(&self) -> Dtype {
        self.dtype
    }
    fn shape(&self) -> &[usize] {
        &self.shape
    }
    fn data(&self) -> Cow<'_, [u8]> {
        Cow::Borrowed(&self.bytes)
    }
    fn data_len(&self) -> usize {
        self.bytes.len()
    }
}

/// The bytes of an f32 array as safetensors stores them (little-endian).
fn f32_bytes(values: &[f32]) -> &[u8] {
    #[cfg(not(target_endian = "little"))]
    compile_error!("buffer files are written by reinterpreting f32 arrays as little-endian bytes");
    // SAFETY: f32 has no padding and no invalid bit patterns as bytes; u8 needs no alignment;
    // the slice covers exactly the array's 4 * len bytes, borrowed for the array's lifetime.
    unsafe { std::slice::from_raw_parts(values.as_ptr().cast::<u8>(), std::mem::size_of_val(values)) }
}

fn column<'a>(dtype: Dtype, len: usize, bytes: Cow<'a, [u8]>) -> Column<'a> {
    Column { dtype, shape: [len], bytes }
}

fn f32_column(values: &[f32]) -> Column<'_> {
    column(Dtype::F32, values.len(), Cow::Borrowed(f32_bytes(values)))
}

fn i64_column(values: impl Iterator<Item = i64>) -> Column<'static> {
    let bytes: Vec<u8> = values.flat_map(i64::to_le_bytes).collect();
    column(Dtype::I64, bytes.len() / 8, Cow::Owned(bytes))
}

/// Writes `buffer` to `path`.
pub fn write(buffer: &ReplayBuffer, path: &Path) -> Result<()> {
    let c = buffer.columns();
    let meta = [c.capacity, c.obs_dim, c.act_dim, c.write, c.len].map(|v| v as i64);
    let columns = [
        ("meta", i64_column(meta.into_iter())),
        ("obs", f32_column(c.obs)),
        ("actions", f32_column(c.actions)),
        ("rewards", f32_column(c.rewards)),
        ("flags", column(Dtype::U8, c.flags.len(), Cow::Borrowed(c.flags))),
        ("side_index", i64_column(c.side_index.iter().map(|&i| i as i64))),
        ("side_values", f32_column(&c.side_values)),
        ("newest_next", f32_column(c.newest_next)),
    ];
    safetensors::serialize_to_file(columns.iter().map(|(n, c)| (*n, c)), None, path)
        .with_context(|| format!("writing {}", path.display()))
}

/// Reads the buffer written to `path`.
pub fn read(path: &Path) -> Result<ReplayBuffer> {
    if !path.exists() {
        anyhow::bail!("checkpoint file {} is missing", path.display());
    }
    let corrupt = || format!("checkpoint file {} is corrupt or unreadable", path.display());
    let file = std::fs::File::open(path).with_context(corrupt)?;
    // SAFETY: the checkpoint is a finished file that nothing writes while it is read (checkpoints
    // are assembled under a temporary name and renamed into place); the map is dropped here.
    let map = unsafe { memmap2::Mmap::map(&file) }.with_context(corrupt)?;
    let tensors = SafeTensors::deserialize(&map).with_context(corrupt)?;
    let get = |name: &str, dtype: Dtype| -> Result<Vec<u8>> {
        let t =
            tensors.tensor(name).with_context(|| format!("{}: buffer checkpoint lacks '{name}'", path.display()))?;
        anyhow::ensure!(t.dtype() == dtype, "{}: '{name}' is {:?}, not {dtype:?}", path.display(), t.dtype());
        Ok(t.data().to_vec())
    };
    let f32s = |name: &str| -> Result<Vec<f32>> {
        let bytes =
            tensors.tensor(name).with_context(|| format!("{}: buffer checkpoint lacks '{name}'", path.display()))?;
        anyhow::ensure!(bytes.dtype() == Dtype::F32, "{}: '{name}' is {:?}, not F32", path.display(), bytes.dtype());
        Ok(bytes.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
    };
    let i64s = |name: &str| -> Result<Vec<i64>> {
        Ok(get(name, Dtype::I64)?.chunks_exact(8).map(|b| i64::from_le_bytes(b.try_into().unwrap())).collect())
    };
    let meta = i64s("meta")?;
    anyhow::ensure!(
        meta.len() == 5 && meta.iter().all(|&v| v >= 0),
        "{}: buffer checkpoint metadata is corrupt",
        path.display()
    );
    let snapshot = BufferSnapshot {
        capacity: meta[0] as usize,
        obs_dim: meta[1] as usize,
        act_dim: meta[2] as usize,
        write: meta[3] as usize,
        len: meta[4] as usize,
        obs: f32s("obs")?,
        actions: f32s("actions")?,
        rewards: f32s("rewards")?,
        flags: get("flags", Dtype::U8)?,
        side_index: i64s("side_index")?.into_iter().map(|i| i as u32).collect(),
        side_values: f32s("side_values")?,
        newest_next: f32s("newest_next")?,
    };
    ReplayBuffer::import(snapshot).with_context(|| path.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled(capacity: usize, steps: usize) -> ReplayBuffer {
        let mut b = ReplayBuffer::new(capacity, 3, 2);
        let mut obs = vec![0.5f32, -1.0, 2.0];
        for t in 0..steps {
            let next: Vec<f32> = obs.iter().map(|v| v * 0.9 + t as f32).collect();
            b.add(&obs, &[t as f32, -0.5], t as f32 * 0.1, &next, t % 7 == 6, t % 5 == 4);
            obs = if t % 5 == 4 { vec![1.0, 1.0, 1.0] } else { next };
        }
        b
    }

    #[test]
    fn a_buffer_round_trips_partial_and_wrapped_and_old_files_still_read() {
        let dir = tempfile::tempdir().unwrap();
        for (capacity, steps) in [(10, 4), (10, 10), (10, 23)] {
            let b = filled(capacity, steps);
            let path = dir.path().join(format!("{capacity}-{steps}.safetensors"));
            write(&b, &path).unwrap();
            assert_eq!(read(&path).unwrap().export(), b.export(), "{capacity} {steps}");
        }
        // The file candle's tensors wrote before this module existed reads the same.
        let b = filled(10, 23);
        let s = b.export();
        let dev = candle_core::Device::Cpu;
        let f = |v: &[f32]| candle_core::Tensor::from_slice(v, v.len(), &dev).unwrap();
        let meta = [s.capacity, s.obs_dim, s.act_dim, s.write, s.len].map(|v| v as i64);
        let side: Vec<i64> = s.side_index.iter().map(|&i| i as i64).collect();
        let tensors: std::collections::HashMap<String, candle_core::Tensor> = [
            ("meta", candle_core::Tensor::from_slice(&meta, 5, &dev).unwrap()),
            ("obs", f(&s.obs)),
            ("actions", f(&s.actions)),
            ("rewards", f(&s.rewards)),
            ("flags", candle_core::Tensor::from_slice(&s.flags, s.flags.len(), &dev).unwrap()),
            ("side_index", candle_core::Tensor::from_slice(&side, side.len(), &dev).unwrap()),
            ("side_values", f(&s.side_values)),
            ("newest_next", f(&s.newest_next)),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        let old = dir.path().join("old.safetensors");
        candle_core::safetensors::save(&tensors, &old).unwrap();
        assert_eq!(read(&old).unwrap().export(), s);
        // ... and what this module writes, candle reads as those tensors.
        let new = dir.path().join("new.safetensors");
        write(&b, &new).unwrap();
        let back = candle_core::safetensors::load(&new, &dev).unwrap();
        assert_eq!(back["obs"].to_vec1::<f32>().unwrap(), s.obs);
        assert_eq!(back["side_index"].to_vec1::<i64>().unwrap(), side);
    }

    #[test]
    fn missing_truncated_and_inconsistent_files_are_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("buffer.safetensors");
        let err = format!("{:#}", read(&path).err().unwrap());
        assert!(err.contains("missing") && err.contains("buffer.safetensors"), "{err}");
        write(&filled(10, 23), &path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 9]).unwrap();
        let err = format!("{:#}", read(&path).err().unwrap());
        assert!(err.contains("corrupt or unreadable") && err.contains("buffer.safetensors"), "{err}");
        // A well-formed file whose arrays disagree with its metadata.
        let mut b = filled(10, 23).export();
        b.obs.pop();
        b.obs.pop();
        b.obs.pop();
        b.len -= 1;
        b.rewards.pop();
        b.flags.pop();
        b.actions.truncate(b.len * b.act_dim);
        b.side_index.push(99);
        b.side_values.extend([0.0; 3]);
        let bad = ReplayBuffer::import(b);
        assert!(bad.is_err(), "an index past the capacity is refused");
    }
}
