//! Writing rendered frames as a video a browser plays (`.mp4`: H.264, `.webm`: VP9, both
//! through the `ffmpeg` program from Debian's `ffmpeg` package, which `scripts/setup.sh`
//! installs) or as a GIF for Markdown (the `gif` crate, in-process). Every file is written under
//! a temporary name beside its destination and renamed into place when complete, so a failure or
//! a kill never leaves half a video.
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use anyhow::{bail, Context, Result};

use super::Frame;

/// The kinds of file a video can be written as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// H.264 in MP4 (`yuv420p`, `+faststart`): plays in every browser.
    Mp4,
    /// VP9 in WebM.
    Webm,
    /// An animated GIF (256 colours per frame), for Markdown pages.
    Gif,
}

impl Format {
    /// From the file's extension; anything else is an error naming it.
    pub fn of(path: &Path) -> Result<Format> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("mp4") => Ok(Format::Mp4),
            Some("webm") => Ok(Format::Webm),
            Some("gif") => Ok(Format::Gif),
            _ => bail!("{}: unsupported video file extension: use .mp4 (H.264), .webm (VP9) or .gif", path.display()),
        }
    }
}

/// How hard MP4 and WebM files are compressed. GIFs are the same at both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Quality {
    /// For videos a user records and watches (`record`, training's evaluation clips).
    #[default]
    Standard,
    /// For the report's clips, which are committed with the results: about half the bytes of
    /// `Standard` (a 50-s 640x240 Ant clip, 0.71 MB against 0.39 MB), with the captions still
    /// legible and the gait clear.
    Compact,
}

impl Quality {
    /// libx264's and libvpx-vp9's constant rate factors (lower is better and larger).
    fn crf(self, format: Format) -> &'static str {
        match (self, format) {
            (Quality::Standard, Format::Webm) => "38",
            (Quality::Compact, Format::Webm) => "44",
            (Quality::Standard, _) => "30",
            (Quality::Compact, _) => "36",
        }
    }

    /// ffmpeg's `-q:v` for a JPEG poster (2 is best, 31 worst).
    fn jpeg(self) -> &'static str {
        match self {
            Quality::Standard => "4",
            Quality::Compact => "7",
        }
    }
}

/// A video being written, frame by frame.
pub struct VideoWriter {
    path: PathBuf,
    // Both taken by `finish`; a writer dropped unfinished stops ffmpeg and removes the file.
    tmp: Option<tempfile::TempPath>,
    width: usize,
    height: usize,
    frames: usize,
    sink: Option<Sink>,
}

enum Sink {
    Ffmpeg(Child),
    Gif(Box<gif::Encoder<std::io::BufWriter<std::fs::File>>>, u16),
}

impl VideoWriter {
    /// Starts `path` (its extension picks the format) for `width` x `height` frames at `fps`.
    /// A path that cannot be written, an unknown extension or a missing `ffmpeg` are errors
    /// before any frame is made.
    pub fn create(path: &Path, width: usize, height: usize, fps: f64) -> Result<VideoWriter> {
        VideoWriter::create_at(path, width, height, fps, Quality::Standard)
    }

    /// [`VideoWriter::create`] at `quality`.
    pub fn create_at(path: &Path, width: usize, height: usize, fps: f64, quality: Quality) -> Result<VideoWriter> {
        let format = Format::of(path)?;
        if !(fps.is_finite() && fps > 0.0 && fps <= 240.0) {
            bail!("frame rate {fps}: must be in (0, 240] frames per second");
        }
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let tmp = tempfile::Builder::new()
            .prefix(".video-")
            .suffix(&format!(".{}", path.extension().unwrap().to_string_lossy()))
            .tempfile_in(dir)
            .with_context(|| format!("cannot write {}: creating a file in {} failed", path.display(), dir.display()))?
            .into_temp_path();
        let sink = match format {
            Format::Gif => {
                let file = std::fs::File::create(&tmp).with_context(|| format!("writing {}", tmp.display()))?;
                let mut encoder = gif::Encoder::new(std::io::BufWriter::new(file), width as u16, height as u16, &[])
                    .context("starting the GIF")?;
                encoder.set_repeat(gif::Repeat::Infinite)?;
                // GIF delays are in hundredths of a second.
                Sink::Gif(Box::new(encoder), (100.0 / fps).round().max(2.0) as u16)
            }
            Format::Mp4 | Format::Webm => Sink::Ffmpeg(ffmpeg(format, &tmp, width, height, fps, quality)?),
        };
        Ok(VideoWriter { path: path.to_path_buf(), tmp: Some(tmp), width, height, frames: 0, sink: Some(sink) })
    }

    /// Appends one frame (of the size the writer was made for).
    pub fn push(&mut self, frame: &Frame) -> Result<()> {
        if frame.width != self.width || frame.height != self.height {
            bail!("frame of {}x{} in a {}x{} video", frame.width, frame.height, self.width, self.height);
        }
        match self.sink.as_mut().expect("a writer being filled has its sink") {
            Sink::Ffmpeg(child) => {
                let stdin = child.stdin.as_mut().context("ffmpeg's input closed")?;
                stdin.write_all(&frame.rgb).context("ffmpeg stopped taking frames")?;
            }
            Sink::Gif(encoder, delay) => {
                // NeuQuant at speed 10: good colours at a few ms per 640x480 frame.
                let mut f = gif::Frame::from_rgb_speed(frame.width as u16, frame.height as u16, &frame.rgb, 10);
                f.delay = *delay;
                encoder.write_frame(&f).context("writing a GIF frame")?;
            }
        }
        self.frames += 1;
        Ok(())
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Finishes the file and moves it to its name; returns the path.
    pub fn finish(mut self) -> Result<PathBuf> {
        if self.frames == 0 {
            bail!("{}: no frames to write", self.path.display());
        }
        let tmp = self.tmp.take().expect("finished once");
        match self.sink.take().expect("finished once") {
            Sink::Ffmpeg(mut child) => {
                drop(child.stdin.take());
                let out = child.wait_with_output().context("waiting for ffmpeg")?;
                if !out.status.success() {
                    bail!(
                        "ffmpeg failed writing {}: {}",
                        self.path.display(),
                        String::from_utf8_lossy(&out.stderr).trim()
                    );
                }
            }
            Sink::Gif(encoder, _) => {
                let mut writer = encoder.into_inner().context("finishing the GIF")?;
                writer.flush()?;
                writer.get_ref().sync_all()?;
            }
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&tmp, std::fs::Permissions::from_mode(0o644))?;
        }
        tmp.persist(&self.path).with_context(|| format!("moving the video to {}", self.path.display()))?;
        Ok(self.path.clone())
    }
}

impl Drop for VideoWriter {
    fn drop(&mut self) {
        // Unfinished: stop ffmpeg before the temporary file goes, so it cannot write it again.
        if let Some(Sink::Ffmpeg(mut child)) = self.sink.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Writes `frame` as the JPEG `path` (a video's poster) at `quality`, through ffmpeg, atomically.
pub fn write_poster(path: &Path, frame: &Frame, quality: Quality) -> Result<PathBuf> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let tmp = tempfile::Builder::new()
        .prefix(".poster-")
        .suffix(".jpg")
        .tempfile_in(dir)
        .with_context(|| format!("cannot write {}: creating a file in {} failed", path.display(), dir.display()))?
        .into_temp_path();
    let size = format!("{}x{}", frame.width, frame.height);
    let mut child = Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", &size])
        .args(["-i", "-", "-frames:v", "1", "-q:v", quality.jpeg(), "-f", "image2", "-c:v", "mjpeg"])
        .arg(&tmp)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("writing {} needs the ffmpeg program (Debian's ffmpeg)", path.display()))?;
    child.stdin.take().context("ffmpeg's input")?.write_all(&frame.rgb)?;
    let out = child.wait_with_output()?;
    if !out.status.success() {
        bail!("ffmpeg failed writing {}: {}", path.display(), String::from_utf8_lossy(&out.stderr).trim());
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&tmp, std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.persist(path).with_context(|| format!("moving the poster to {}", path.display()))?;
    Ok(path.to_path_buf())
}

/// Checks that `format` can be written here (`ffmpeg` for MP4 and WebM), for an error before
/// long work starts rather than at its first video.
pub fn check_encoder(format: Format) -> Result<()> {
    if format == Format::Gif {
        return Ok(());
    }
    let ok = Command::new("ffmpeg")
        .args(["-hide_banner", "-version"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        bail!("writing MP4 or WebM videos needs the ffmpeg program: install Debian's ffmpeg (`apt-get install ffmpeg`, which scripts/setup.sh does)");
    }
    Ok(())
}

fn ffmpeg(format: Format, out: &Path, width: usize, height: usize, fps: f64, quality: Quality) -> Result<Child> {
    let crf = quality.crf(format);
    let codec: &[&str] = match format {
        // yuv420p and even sizes: what browsers' H.264 decoders take; faststart: playable while
        // loading. medium at CRF 30 made a 10-s 640x240 Ant clip 20% smaller than veryfast at 28,
        // for about 1 s more per clip.
        Format::Mp4 => {
            &["-c:v", "libx264", "-preset", "medium", "-crf", crf, "-pix_fmt", "yuv420p", "-movflags", "+faststart"]
        }
        _ => &[
            "-c:v",
            "libvpx-vp9",
            "-b:v",
            "0",
            "-crf",
            crf,
            "-deadline",
            "realtime",
            "-cpu-used",
            "8",
            "-row-mt",
            "1",
            "-pix_fmt",
            "yuv420p",
        ],
    };
    let size = format!("{width}x{height}");
    let rate = format!("{fps}");
    // Odd sizes are padded by a pixel: yuv420p needs even ones.
    let pad = "pad=ceil(iw/2)*2:ceil(ih/2)*2";
    Command::new("ffmpeg")
        .args([
            "-hide_banner",
            "-loglevel",
            "error",
            "-y",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "-s",
            &size,
            "-r",
            &rate,
        ])
        .args(["-i", "-", "-vf", pad, "-an"])
        .args(codec)
        .args(["-f", if format == Format::Mp4 { "mp4" } else { "webm" }])
        .arg(out)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| {
            anyhow::anyhow!(
                "writing {} needs the ffmpeg program ({e}); install Debian's ffmpeg (`apt-get install ffmpeg`, which \
                 scripts/setup.sh does), or write a .gif, which needs nothing",
                out.display()
            )
        })
}
