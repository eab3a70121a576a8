//! Offscreen rendering: known states give frames whose pixels are where the robot is, the same
//! state gives the same bytes, the follow camera keeps the robot centred, videos come out with
//! the frames asked for, and bad input is a clear error. OSMesa (the default) and EGL (Mesa's
//! surfaceless platform on a machine without a GPU) are both checked.
use std::sync::Arc;

use locobench::envs::{make, Env, EnvConfig};
use locobench::mujoco::Model;
use locobench::render::video::VideoWriter;
use locobench::render::{Backend, Camera, Frame, Marks, RenderSettings, Renderer};

const W: usize = 160;
const H: usize = 120;

fn minitaur() -> Box<dyn Env> {
    let mut env = make(&EnvConfig::new("minitaur")).unwrap();
    env.reset(Some(0)).unwrap();
    env
}

fn model(env: &dyn Env) -> Arc<Model> {
    env.data().model().clone()
}

/// Moves the robot's free base by `dx` along x (and `dz` up) and renders.
fn render_moved(env: &mut dyn Env, renderer: &mut Renderer, dx: f64, dz: f64) -> Frame {
    let (mut qpos, qvel) = (env.data().qpos().to_vec(), env.data().qvel().to_vec());
    qpos[0] += dx;
    qpos[2] += dz;
    env.set_state(&qpos, &qvel).unwrap();
    let frame = renderer.render(env.data()).unwrap();
    qpos[0] -= dx;
    qpos[2] -= dz;
    env.set_state(&qpos, &qvel).unwrap();
    frame
}

/// The centre (x, y in pixels) and size of the pixels that differ from `background`.
fn silhouette(frame: &Frame, background: &Frame) -> (f64, f64, usize) {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for y in 0..frame.height {
        for x in 0..frame.width {
            let (a, b) = (frame.pixel(x, y), background.pixel(x, y));
            let diff: i32 = (0..3).map(|k| (a[k] as i32 - b[k] as i32).abs()).sum();
            if diff > 40 {
                sx += x as f64;
                sy += y as f64;
                n += 1;
            }
        }
    }
    assert!(n > 0, "no robot pixels in the frame");
    (sx / n as f64, sy / n as f64, n)
}

fn free_side_camera() -> RenderSettings {
    // From the side (looking along +y), level with the base, 1.5 m away.
    RenderSettings { width: W, height: H, camera: Camera::Free { distance: 1.5, azimuth: 90.0, elevation: 0.0 } }
}

fn robot_sits_where_its_base_is_and_moves_with_it(backend: Backend) {
    let mut env = minitaur();
    let mut renderer = Renderer::with_backend(&model(env.as_ref()), free_side_camera(), backend).unwrap();
    let background = render_moved(env.as_mut(), &mut renderer, 0.0, 100.0);
    let at_origin = renderer.render(env.data()).unwrap();
    let (x0, y0, n0) = silhouette(&at_origin, &background);
    // The camera looks at the base's starting point: the robot is in the middle of the frame.
    assert!((x0 - W as f64 / 2.0).abs() < 0.06 * W as f64, "robot centred at x {x0:.1} of {W}");
    assert!((y0 - H as f64 / 2.0).abs() < 0.2 * H as f64, "robot centred at y {y0:.1} of {H}");
    assert!(n0 > 200 && n0 < W * H / 2, "a robot-sized silhouette: {n0} pixels");

    // 0.2 m along x: the silhouette moves by the camera's projection of 0.2 m at 1.5 m (fovy 45
    // degrees: H/2 / tan(22.5) pixels per unit of depth-scaled length), to the right as seen
    // from -y.
    let moved = render_moved(env.as_mut(), &mut renderer, 0.2, 0.0);
    let (x1, y1, _) = silhouette(&moved, &background);
    let expected = (H as f64 / 2.0) / (22.5f64.to_radians().tan()) * 0.2 / 1.5;
    let shift = x1 - x0;
    assert!((shift - expected).abs() < 0.25 * expected, "moved {shift:.1} px, expected about {expected:.1}");
    assert!((y1 - y0).abs() < 2.0, "moving along x moved the robot vertically: {y0:.1} -> {y1:.1}");

    // Same state, same bytes.
    assert_eq!(renderer.render(env.data()).unwrap(), at_origin);
}

#[test]
fn osmesa_renders_the_robot_where_it_is() {
    robot_sits_where_its_base_is_and_moves_with_it(Backend::OsMesa);
}

/// Run by the EGL test in a process of its own: MuJoCo loads its GL functions once per process,
/// from whichever library is there, so one process renders on one backend (as `MUJOCO_GL`
/// chooses for a whole program in Gymnasium too).
#[test]
#[ignore = "run in its own process by egl_renders_the_robot_where_it_is"]
fn robot_placement_on_the_backend_mujoco_gl_names() {
    robot_sits_where_its_base_is_and_moves_with_it(Backend::from_env().unwrap());
}

#[test]
fn egl_renders_the_robot_where_it_is() {
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--ignored", "--exact", "robot_placement_on_the_backend_mujoco_gl_names", "--nocapture"])
        .env("MUJOCO_GL", "egl")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && stdout.contains("1 passed"), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn the_follow_camera_keeps_the_robot_centred() {
    let mut env = minitaur();
    let settings = RenderSettings { width: W, height: H, camera: Camera::Follow };
    let mut renderer = Renderer::with_backend(&model(env.as_ref()), settings, Backend::OsMesa).unwrap();
    let here = renderer.render(env.data()).unwrap();
    let there = render_moved(env.as_mut(), &mut renderer, 3.0, 0.0);
    // The robot's body is blue and the floor grey: its blue pixels sit in the middle of both
    // frames, in the same number (the floor's checker moves under it).
    let blue = |f: &Frame| {
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
        for y in 0..H {
            for x in 0..W {
                let [r, _, b] = f.pixel(x, y);
                if b as i32 > r as i32 + 60 {
                    sx += x as f64;
                    sy += y as f64;
                    n += 1;
                }
            }
        }
        assert!(n > 50, "the robot's body in the frame ({n} blue pixels)");
        (sx / n as f64, sy / n as f64, n as f64)
    };
    let ((x0, y0, n0), (x1, y1, n1)) = (blue(&here), blue(&there));
    for (x, y) in [(x0, y0), (x1, y1)] {
        assert!(
            (x - W as f64 / 2.0).abs() < 0.1 * W as f64 && (y - H as f64 / 2.0).abs() < 0.2 * H as f64,
            "({x:.0}, {y:.0})"
        );
    }
    assert!((x1 - x0).abs() < 2.0 && (y1 - y0).abs() < 2.0 && (n1 / n0 - 1.0).abs() < 0.1, "{n0} and {n1} blue pixels");
}

#[test]
fn bad_render_settings_are_clear_errors() {
    let env = minitaur();
    let m = model(env.as_ref());
    let err =
        |settings: RenderSettings| Renderer::with_backend(&m, settings, Backend::OsMesa).err().unwrap().to_string();
    assert!(err(RenderSettings { width: 8, ..free_side_camera() }).contains("16 to 4096"));
    let unknown = err(RenderSettings { camera: Camera::Fixed("top".into()), ..free_side_camera() });
    assert!(unknown.contains("unknown camera 'fixed:top'"), "{unknown}");
    for (spec, expect) in [
        ("side", "unknown camera 'side'"),
        ("free:1,2", "three finite numbers"),
        ("free:-1,0,0", "the distance > 0"),
        ("fixed:", "needs the model camera's name"),
    ] {
        let e = Camera::parse(spec).unwrap_err().to_string();
        assert!(e.contains(expect), "{spec}: {e}");
    }
    assert_eq!(
        Camera::parse("free:2,90,-20").unwrap(),
        Camera::Free { distance: 2.0, azimuth: 90.0, elevation: -20.0 }
    );
    assert!(Backend::parse("vulkan").unwrap_err().to_string().contains("osmesa (the default) or egl"));
}

fn frames(n: usize) -> Vec<Frame> {
    (0..n)
        .map(|i| Frame { width: 32, height: 24, rgb: (0..32 * 24 * 3).map(|k| ((k + 7 * i) % 256) as u8).collect() })
        .collect()
}

#[test]
fn videos_hold_the_frames_written_and_bad_paths_are_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let gif = dir.path().join("v.gif");
    let mut w = VideoWriter::create(&gif, 32, 24, 25.0).unwrap();
    for f in frames(5) {
        w.push(&f).unwrap();
    }
    assert!(w.push(&Frame { width: 8, height: 8, rgb: vec![0; 192] }).unwrap_err().to_string().contains("8x8"));
    w.finish().unwrap();
    let mut decoder = gif::DecodeOptions::new().read_info(std::fs::File::open(&gif).unwrap()).unwrap();
    let mut count = 0;
    while let Some(frame) = decoder.read_next_frame().unwrap() {
        assert_eq!((frame.width, frame.height, frame.delay), (32, 24, 4));
        count += 1;
    }
    assert_eq!(count, 5);

    for (path, expect) in [
        (dir.path().join("v.avi"), "unsupported video file extension"),
        (dir.path().join("no/such/dir/v.gif"), "cannot write"),
    ] {
        let e = VideoWriter::create(&path, 32, 24, 25.0).err().unwrap().to_string();
        assert!(e.contains(expect), "{}: {e}", path.display());
    }
    // Nothing half-written is left: only the finished GIF.
    let names: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(names, ["v.gif"]);
    // A writer dropped before it finished leaves nothing either.
    drop(VideoWriter::create(&dir.path().join("w.gif"), 32, 24, 25.0).unwrap());
    assert!(!dir.path().join("w.gif").exists() && std::fs::read_dir(dir.path()).unwrap().count() == 1);
}

/// `record --video` films any policy; the MP4 holds a frame per stride of steps (and the first),
/// which ffprobe (Debian's ffmpeg) counts.
#[test]
fn record_writes_a_video_with_one_frame_per_stride() {
    let dir = tempfile::tempdir().unwrap();
    let mp4 = dir.path().join("random.mp4");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_locobench"))
        .args(["record", "--env", "minitaur", "--policy", "random", "--option", "max_episode_steps=40"])
        .args(["--width", "160", "--height", "120", "--video"])
        .arg(&mp4)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(!dir.path().join("rollout.rrd").exists(), "--video alone writes no rerun recording");
    let probe = std::process::Command::new("ffprobe")
        .args(["-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries"])
        .args(["stream=nb_read_frames,width,height,codec_name", "-of", "csv=p=0"])
        .arg(&mp4)
        .output()
        .expect("ffprobe (Debian's ffmpeg, installed by scripts/setup.sh)");
    // Minitaur acts at 100 Hz: a frame every 4 steps at 25 fps, plus the reset's.
    assert_eq!(String::from_utf8_lossy(&probe.stdout).trim(), "h264,160,120,11");
}

/// `train --video-every N` films the evaluation episode on an env of its own: the run's numbers
/// are the same bytes with and without clips, and a clip is written at every N-th evaluation.
#[test]
fn training_clips_leave_the_run_s_numbers_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let train = |out: &std::path::Path, extra: &[&str]| {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_locobench"))
            .args(["train", "--env", "inverted-pendulum", "--algo", "td3", "--steps", "900", "--quiet"])
            .args([
                "--set",
                "hidden=[16,16],batch_size=32,warmup_steps=100,learning_starts=100,eval_every=300,eval_episodes=1",
            ])
            .arg("--out")
            .arg(out)
            .args(extra)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    let (plain, filmed) = (dir.path().join("plain"), dir.path().join("filmed"));
    train(&plain, &[]);
    train(&filmed, &["--video-every", "2"]);
    let numbers = |run: &std::path::Path| -> Vec<String> {
        std::fs::read_to_string(run.join("metrics.csv"))
            .unwrap()
            .lines()
            .map(|l| {
                l.split(',')
                    .enumerate()
                    .filter(|(i, _)| *i != 9 && *i != 10)
                    .map(|(_, v)| v)
                    .collect::<Vec<_>>()
                    .join(",")
            })
            .collect()
    };
    assert_eq!(numbers(&plain), numbers(&filmed));
    let weights = |run: &std::path::Path| std::fs::read(run.join("policies/step-900.safetensors")).unwrap();
    assert_eq!(weights(&plain), weights(&filmed));
    // Evaluations at 300, 600 and 900: clips at the first and the third.
    let mut clips: Vec<String> = std::fs::read_dir(filmed.join("videos"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    clips.sort();
    assert_eq!(clips, ["eval-step-300.gif", "eval-step-300.mp4", "eval-step-900.gif", "eval-step-900.mp4"]);
    let gif = std::fs::read(filmed.join("videos/eval-step-300.gif")).unwrap();
    assert!(gif.starts_with(b"GIF89a"), "a GIF copy for Markdown and TensorBoard");

    // `report --progress` shows the clips in training order, each with its evaluation.
    let page = dir.path().join("progress");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_locobench"))
        .args(["report", "--progress"])
        .arg(&filmed)
        .arg("--out")
        .arg(&page)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let html = std::fs::read_to_string(page.join("index.html")).unwrap();
    let md = std::fs::read_to_string(page.join("README.md")).unwrap();
    let (first, last) =
        (html.find("videos/eval-step-300.mp4").unwrap(), html.find("videos/eval-step-900.mp4").unwrap());
    assert!(first < last, "training order");
    assert!(md.contains("![step 300 (300): evaluation return") && md.contains("](videos/eval-step-900.gif)"), "{md}");
    for f in ["eval-step-300.mp4", "eval-step-300.gif", "eval-step-900.mp4", "eval-step-900.gif"] {
        assert_eq!(
            std::fs::read(page.join("videos").join(f)).unwrap(),
            std::fs::read(filmed.join("videos").join(f)).unwrap(),
            "{f} copied beside the page"
        );
    }
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_locobench"))
        .args(["report", "--progress"])
        .arg(&plain)
        .arg("--out")
        .arg(dir.path().join("none"))
        .output()
        .unwrap();
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--video-every"));
}

/// A caption is drawn at the top left and leaves the rest of the frame as it was.
#[test]
fn a_caption_is_drawn_at_the_top_left_only() {
    let env = minitaur();
    let settings = RenderSettings { width: 320, height: 240, camera: Camera::Follow };
    let mut renderer = Renderer::with_backend(&model(env.as_ref()), settings, Backend::OsMesa).unwrap();
    let plain = renderer.render(env.data()).unwrap();
    let marks = Marks { caption: Some(("ppo 1M\nstep 0".into(), String::new())), arrow: None };
    let captioned = renderer.render_marked(env.data(), &marks).unwrap();
    let changed = |x0: usize, x1: usize, y0: usize, y1: usize| {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| plain.pixel(x, y) != captioned.pixel(x, y))
            .count()
    };
    assert!(changed(0, 160, 0, 60) > 500, "the caption's box and text at the top left");
    assert_eq!(changed(0, 320, 120, 240), 0, "the lower half untouched");
    assert_eq!(changed(200, 320, 0, 240), 0, "the right side untouched");
}

/// A pushed episode is marked while the push acts and for a second after: red arrow pixels
/// appear then and not before, and the panel says when the push began.
#[test]
fn a_push_is_marked_in_the_frame_while_it_acts() {
    use locobench::evaluation::Push;
    use locobench::policy::ZeroPolicy;
    use locobench::render::clip::film_episode;
    let cfg = EnvConfig::new("minitaur").with_overrides(&[("max_episode_steps".into(), "700".into())]).unwrap();
    let settings = RenderSettings { width: W, height: H, camera: Camera::Follow };
    let panel = film_episode(&cfg, &mut ZeroPolicy, &settings, 10.0, 7, None, Some(Push::lateral(0.5))).unwrap();
    let start = panel.push_time.expect("the push is seen");
    assert!((2.0..6.0).contains(&start), "the evaluation pushes 2-6 s in, not at {start}");
    let red = |f: &Frame| {
        (0..f.height)
            .flat_map(|y| (0..f.width).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let [r, g, b] = f.pixel(x, y);
                r > 150 && g < 60 && b < 60
            })
            .count()
    };
    let time = |i: usize| i as f64 / panel.fps;
    for (i, f) in panel.frames.iter().enumerate() {
        let t = time(i);
        if t < start - 0.05 || t > start + 1.2 {
            assert_eq!(red(f), 0, "no arrow at {t:.1} s (push at {start:.2} s)");
        } else if t > start + 0.15 && t < start + 0.9 {
            assert!(red(f) > 20, "the arrow at {t:.1} s (push at {start:.2} s)");
        }
    }
    let unpushed = film_episode(&cfg, &mut ZeroPolicy, &settings, 10.0, 7, None, None).unwrap();
    assert!(unpushed.push_time.is_none());
}

/// `--side-by-side controller`: the policy's panel and the controller's in one frame, the same
/// episode for both; without a video or with several episodes it is refused.
#[test]
fn side_by_side_puts_the_controller_beside_the_policy() {
    let dir = tempfile::tempdir().unwrap();
    let mp4 = dir.path().join("sbs.mp4");
    let record = |extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_locobench"))
            .args(["record", "--env", "minitaur", "--policy", "zero", "--option", "max_episode_steps=20"])
            .args(["--width", "160", "--height", "120", "--side-by-side", "controller"])
            .args(extra)
            .output()
            .unwrap()
    };
    let out = record(&["--video", mp4.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("next: controller at") && stdout.contains("2 panels"), "{stdout}");
    let probe = std::process::Command::new("ffprobe")
        .args(["-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries"])
        .args(["stream=nb_read_frames,width,height", "-of", "csv=p=0"])
        .arg(&mp4)
        .output()
        .unwrap();
    // Two 160-pixel panels; 20 steps at a frame every 4, and the reset's.
    assert_eq!(String::from_utf8_lossy(&probe.stdout).trim(), "320,120,6");
    let refused = record(&[]);
    assert!(String::from_utf8_lossy(&refused.stderr).contains("give --video FILE"));
    let refused = record(&["--video", mp4.to_str().unwrap(), "--episodes", "2"]);
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--episodes 1"));
}

#[test]
fn tiled_panels_hold_their_last_frame() {
    use locobench::render::tile;
    let f = |w: usize, v: u8| Frame { width: w, height: 2, rgb: vec![v; w * 2 * 3] };
    let tiled = tile(&[vec![f(1, 1), f(1, 2)], vec![f(2, 9)]]).unwrap();
    assert_eq!(tiled.len(), 2);
    assert_eq!((tiled[1].width, tiled[1].height), (3, 2));
    assert_eq!(tiled[1].pixel(0, 1), [2, 2, 2]);
    assert_eq!(tiled[1].pixel(2, 0), [9, 9, 9], "the shorter panel holds its last frame");
    assert!(tile(&[vec![f(1, 1)], vec![Frame { width: 1, height: 3, rgb: vec![0; 9] }]]).is_err());
}

/// The report's compact encoding (its clips are committed) writes the same frames as the standard
/// one in fewer bytes, for MP4, WebM and the JPEG poster alike.
#[test]
fn compact_videos_hold_the_same_frames_in_fewer_bytes() {
    use locobench::render::clip::write_video_at;
    use locobench::render::video::{write_poster, Quality};
    let mut env = minitaur();
    let mut renderer = Renderer::new(&model(env.as_ref()), free_side_camera()).unwrap();
    let clip: Vec<Frame> = (0..30).map(|i| render_moved(env.as_mut(), &mut renderer, 0.01 * i as f64, 0.0)).collect();
    let dir = tempfile::tempdir().unwrap();
    let bytes = |p: &std::path::Path| std::fs::metadata(p).unwrap().len();
    for ext in ["mp4", "webm"] {
        let standard = write_video_at(&dir.path().join(format!("s.{ext}")), &clip, 25.0, Quality::Standard).unwrap();
        let compact = write_video_at(&dir.path().join(format!("c.{ext}")), &clip, 25.0, Quality::Compact).unwrap();
        assert!(bytes(&compact) < bytes(&standard), "{ext}: {} against {}", bytes(&compact), bytes(&standard));
        for path in [&standard, &compact] {
            let probe = std::process::Command::new("ffprobe")
                .args(["-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries"])
                .args(["stream=nb_read_frames,width,height", "-of", "csv=p=0"])
                .arg(path)
                .output()
                .expect("ffprobe (Debian's ffmpeg, installed by scripts/setup.sh)");
            assert_eq!(String::from_utf8_lossy(&probe.stdout).trim(), format!("{W},{H},30"), "{}", path.display());
        }
    }
    let standard = write_poster(&dir.path().join("s.jpg"), &clip[15], Quality::Standard).unwrap();
    let compact = write_poster(&dir.path().join("c.jpg"), &clip[15], Quality::Compact).unwrap();
    assert!(bytes(&compact) < bytes(&standard) && std::fs::read(&compact).unwrap().starts_with(&[0xff, 0xd8]));
}
