//! TensorBoard event files (`train --tensorboard DIR`): every value of every `metrics.csv` row as
//! a scalar, tagged `<kind>/<column>` (`episode/episode_return`, `eval/eval_mean`,
//! `eval/eval_std`, `episode/critic_loss`, ...) at the row's step, so TensorBoard (and Weights &
//! Biases, which imports these files with `wandb sync --sync-tensorboard`) shows the curves
//! `metrics.csv` holds, and with `--video-every` the evaluation clips as animated GIF images
//! (`eval/video`).
//!
//! The format is TensorFlow's: a file `events.out.tfevents.<seconds>.<host>` of records, each a
//! little-endian u64 length, its masked CRC-32C, the bytes of one `Event` protocol buffer and
//! their masked CRC-32C (tensorflow/core/lib/io/record_writer.cc); the messages are those of
//! tensorflow/core/util/event.proto and summary.proto, written here with prost. Every file
//! starts with a `SessionLog` START event one step past where the run continues from: TensorBoard
//! then drops what a stopped or killed stretch logged after that point, which the resumed run
//! logs again (tensorboard's `EventAccumulator` purges on START).
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use prost::Message;

use super::metrics::MetricsRow;

#[derive(Clone, PartialEq, prost::Message)]
struct Event {
    #[prost(double, tag = "1")]
    wall_time: f64,
    #[prost(int64, tag = "2")]
    step: i64,
    #[prost(oneof = "What", tags = "3, 5, 7")]
    what: Option<What>,
}

#[derive(Clone, PartialEq, prost::Oneof)]
enum What {
    #[prost(string, tag = "3")]
    FileVersion(String),
    #[prost(message, tag = "5")]
    Summary(Summary),
    // 6 is the deprecated log_message.
    #[prost(message, tag = "7")]
    SessionLog(SessionLog),
}

#[derive(Clone, PartialEq, prost::Message)]
struct Summary {
    #[prost(message, repeated, tag = "1")]
    value: Vec<SummaryValue>,
}

#[derive(Clone, PartialEq, prost::Message)]
struct SummaryValue {
    #[prost(string, tag = "1")]
    tag: String,
    // A member of summary.proto's `oneof value`, so written even when 0 (a plain proto3 float
    // field would leave a zero out, and TensorBoard would drop the point).
    #[prost(oneof = "Scalar", tags = "2, 4")]
    value: Option<Scalar>,
}

#[derive(Clone, PartialEq, prost::Oneof)]
enum Scalar {
    #[prost(float, tag = "2")]
    SimpleValue(f32),
    #[prost(message, tag = "4")]
    Image(Image),
}

/// summary.proto's `Summary.Image`: an encoded image (PNG, JPEG or GIF; an animated GIF plays
/// in TensorBoard's image dashboard, which is how video summaries are shown).
#[derive(Clone, PartialEq, prost::Message)]
struct Image {
    #[prost(int32, tag = "1")]
    height: i32,
    #[prost(int32, tag = "2")]
    width: i32,
    /// 3: RGB.
    #[prost(int32, tag = "3")]
    colorspace: i32,
    #[prost(bytes = "vec", tag = "4")]
    encoded_image_string: Vec<u8>,
}

#[derive(Clone, PartialEq, prost::Message)]
struct SessionLog {
    /// 1: START.
    #[prost(int32, tag = "1")]
    status: i32,
}

/// TensorFlow's masked CRC-32C of a record's parts.
fn masked_crc(bytes: &[u8]) -> u32 {
    let crc = crc32c::crc32c(bytes);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

/// One run's event file, appended to as rows come.
pub(crate) struct EventWriter {
    path: PathBuf,
    file: std::io::BufWriter<std::fs::File>,
}

fn now() -> f64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs_f64()).unwrap_or(0.0)
}

impl EventWriter {
    /// A new event file in `dir` for a run that continues from step `start` (0 for a new run):
    /// its first event after the file version tells TensorBoard to drop anything an earlier
    /// file logged past `start` (a stretch that was stopped or killed and is now computed again,
    /// or a run started afresh).
    pub(crate) fn create(dir: &Path, start: u64) -> Result<EventWriter> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating TensorBoard directory {}", dir.display()))?;
        let wall = now();
        let host = super::run_lock::hostname();
        // Seconds and a sequence number: two files started within a second stay in order.
        let mut n = 0;
        let path = loop {
            let candidate = dir.join(format!("events.out.tfevents.{:010}.{host}.{n}", wall as u64));
            if !candidate.exists() {
                break candidate;
            }
            n += 1;
        };
        let file = std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        let mut writer = EventWriter { path, file: std::io::BufWriter::new(file) };
        writer.write(&Event { wall_time: wall, step: 0, what: Some(What::FileVersion("brain.Event:2".into())) })?;
        // TensorBoard keeps what came before with a step below the START event's.
        let session = What::SessionLog(SessionLog { status: 1 });
        writer.write(&Event { wall_time: wall, step: start as i64 + 1, what: Some(session) })?;
        writer.flush()?;
        Ok(writer)
    }

    fn write(&mut self, event: &Event) -> Result<()> {
        let data = event.encode_to_vec();
        let length = (data.len() as u64).to_le_bytes();
        let record = [&length[..], &masked_crc(&length).to_le_bytes(), &data, &masked_crc(&data).to_le_bytes()];
        for part in record {
            self.file.write_all(part).with_context(|| format!("writing {}", self.path.display()))?;
        }
        Ok(())
    }

    /// Logs every value `row` carries, as `metrics.csv` holds it, at its step.
    pub(crate) fn row(&mut self, row: &MetricsRow) -> Result<()> {
        let value = row
            .values()
            .into_iter()
            .filter_map(|(column, v)| {
                v.map(|v| SummaryValue {
                    tag: format!("{}/{column}", row.kind),
                    value: Some(Scalar::SimpleValue(v as f32)),
                })
            })
            .collect();
        self.write(&Event { wall_time: now(), step: row.step as i64, what: Some(What::Summary(Summary { value })) })?;
        // Evaluations are rare: flushed at once, so TensorBoard shows them while the run goes on.
        if row.kind == "eval" {
            self.flush()?;
        }
        Ok(())
    }

    /// Logs the GIF file `gif` (`width` x `height`) as the image `tag` at `step`.
    pub(crate) fn gif(&mut self, tag: &str, step: u64, gif: &Path, width: usize, height: usize) -> Result<()> {
        let bytes = std::fs::read(gif).with_context(|| format!("reading {}", gif.display()))?;
        let image = Image { height: height as i32, width: width as i32, colorspace: 3, encoded_image_string: bytes };
        let value = vec![SummaryValue { tag: tag.to_string(), value: Some(Scalar::Image(image)) }];
        self.write(&Event { wall_time: now(), step: step as i64, what: Some(What::Summary(Summary { value })) })?;
        self.flush()
    }

    /// Writes what is buffered to the file.
    pub(crate) fn flush(&mut self) -> Result<()> {
        self.file.flush().with_context(|| format!("writing {}", self.path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    // The mask spelled out as TensorFlow's crc32c::Mask writes it, not as the code computes it.
    #[allow(clippy::manual_rotate)]
    fn records_carry_tensorflows_masked_crc32c() {
        // CRC-32C of "123456789" is 0xe3069283 (RFC 3720's check value); masked as TensorFlow's
        // crc32c::Mask does.
        assert_eq!(crc32c::crc32c(b"123456789"), 0xe306_9283);
        let expected = ((0xe306_9283u32 >> 15) | (0xe306_9283u32 << 17)).wrapping_add(0xa282_ead8);
        assert_eq!(masked_crc(b"123456789"), expected);
        let dir = tempfile::tempdir().unwrap();
        let mut w = EventWriter::create(dir.path(), 40).unwrap();
        w.row(&MetricsRow { kind: "eval", step: 50, eval_mean: Some(2.5), ..Default::default() }).unwrap();
        w.flush().unwrap();
        let bytes = std::fs::read(&w.path).unwrap();
        // Walk the records: each length and payload checks out, three events in all.
        let (mut at, mut events) = (0, Vec::new());
        while at < bytes.len() {
            let len = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
            assert_eq!(u32::from_le_bytes(bytes[at + 8..at + 12].try_into().unwrap()), masked_crc(&bytes[at..at + 8]));
            let data = &bytes[at + 12..at + 12 + len];
            assert_eq!(u32::from_le_bytes(bytes[at + 12 + len..at + 16 + len].try_into().unwrap()), masked_crc(data));
            events.push(Event::decode(data).unwrap());
            at += 16 + len;
        }
        assert_eq!(events.len(), 3);
        assert_eq!(events[0].what, Some(What::FileVersion("brain.Event:2".into())));
        assert_eq!((events[1].step, events[1].what.clone()), (41, Some(What::SessionLog(SessionLog { status: 1 }))));
        let Some(What::Summary(s)) = &events[2].what else { panic!("not a summary") };
        assert_eq!(events[2].step, 50);
        assert!(s.value.iter().any(|v| v.tag == "eval/eval_mean" && v.value == Some(Scalar::SimpleValue(2.5))));
        // A zero is written too.
        let zero = SummaryValue { tag: "t".into(), value: Some(Scalar::SimpleValue(0.0)) };
        assert_eq!(SummaryValue::decode(zero.encode_to_vec().as_slice()).unwrap(), zero);
    }
}
