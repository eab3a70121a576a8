//! Recordings read back with rerun's own decoder: entity paths, frame count, and logged body
//! transforms against MuJoCo's `xpos`/`xquat`.
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use anyhow::Result;
use locobench::envs::{make, Env, EnvConfig};
use locobench::policy::RandomPolicy;
use locobench::record::{Recording, RolloutRecorder};
use locobench::rollout::{run_episodes, EpisodeSummary, Observer, StepView};
use rerun::log::{Chunk, LogMsg};

mod common;
use common::locobench_with_path;

fn read_chunks(path: &Path) -> Vec<Chunk> {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    re_log_encoding::DecoderApp::decode_lazy(file)
        .filter_map(|msg| match msg.expect("a valid rrd message") {
            LogMsg::ArrowMsg(_, arrow) => Some(Chunk::from_arrow_msg(&arrow).expect("a valid chunk")),
            _ => None,
        })
        .collect()
}

fn entity_paths(chunks: &[Chunk]) -> BTreeSet<String> {
    chunks.iter().map(|c| c.entity_path().to_string().trim_start_matches('/').to_string()).collect()
}

/// Every value of `timeline` that any chunk has a row at.
fn timeline_values(chunks: &[Chunk], timeline: &'static str) -> BTreeSet<i64> {
    chunks
        .iter()
        .filter(|c| !c.is_static())
        .flat_map(|c| {
            let name = timeline.into();
            c.iter_indices(&name).map(|(t, _)| t.as_i64()).collect::<Vec<_>>()
        })
        .collect()
}

/// Translation and quaternion (x, y, z, w) logged for `entity`, by `step`.
fn transforms(chunks: &[Chunk], entity: &str) -> BTreeMap<i64, ([f32; 3], [f32; 4])> {
    let translation = rerun::Transform3D::descriptor_translation().component;
    let quaternion = rerun::Transform3D::descriptor_quaternion().component;
    let mut out = BTreeMap::new();
    for c in chunks.iter().filter(|c| c.entity_path().to_string().trim_start_matches('/') == entity) {
        let steps: Vec<i64> = c.iter_component_indices("step".into(), translation).map(|(t, _)| t.as_i64()).collect();
        let ts: Vec<[f32; 3]> =
            c.iter_component::<rerun::components::Translation3D>(translation).map(|b| b[0].0.into()).collect();
        let qs: Vec<[f32; 4]> =
            c.iter_component::<rerun::components::RotationQuat>(quaternion).map(|b| b[0].0.into()).collect();
        assert_eq!(steps.len(), ts.len());
        assert_eq!(ts.len(), qs.len());
        for ((s, t), q) in steps.into_iter().zip(ts).zip(qs) {
            out.insert(s, (t, q));
        }
    }
    out
}

/// Keeps the torso pose MuJoCo had at every frame, then passes the frame on to the recorder.
struct Witness<'a> {
    recorder: RolloutRecorder<'a>,
    torso: usize,
    poses: Vec<([f64; 3], [f64; 4])>,
}

impl Witness<'_> {
    fn keep(&mut self, env: &dyn Env) {
        let d = env.data();
        let (p, q) = (&d.xpos()[3 * self.torso..], &d.xquat()[4 * self.torso..]);
        self.poses.push(([p[0], p[1], p[2]], [q[0], q[1], q[2], q[3]]));
    }
}

impl Observer for Witness<'_> {
    fn reset(&mut self, episode: usize, env: &dyn Env) -> Result<()> {
        self.keep(env);
        self.recorder.reset(episode, env)
    }
    fn step(&mut self, view: &StepView) -> Result<()> {
        self.keep(view.env);
        self.recorder.step(view)
    }
    fn end(&mut self, summary: &EpisodeSummary) -> Result<()> {
        self.recorder.end(summary)
    }
}

#[test]
fn ant_rollout_reads_back_with_poses_series_and_scene() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ant.rrd");
    let cfg = EnvConfig::new("ant").with_overrides(&[("max_episode_steps".into(), "25".into())]).unwrap();
    let mut env = make(&cfg).unwrap();
    let torso = env.data().model().body_id("torso").unwrap();
    let recording = Recording::create(&path).unwrap();
    let recorder = RolloutRecorder::new(recording.stream(), env.data().model()).unwrap();
    let mut witness = Witness { recorder, torso, poses: Vec::new() };
    let summaries = run_episodes(env.as_mut(), &mut RandomPolicy::new(3), 2, 0, &mut witness).unwrap();
    let scene = witness.recorder.scene.clone();
    let poses = std::mem::take(&mut witness.poses);
    drop(witness);
    recording.finish().unwrap();
    assert_eq!(summaries.iter().map(|s| s.length).sum::<usize>(), 50);

    let chunks = read_chunks(&path);
    let paths = entity_paths(&chunks);
    for expected in [
        "world/floor",
        "world/torso",
        "world/torso/torso_geom",
        "world/front_left_leg/aux_1_geom",
        "world/aux_1/left_leg_geom",
        "world/contacts/points",
        "world/contacts/forces",
        "plots/reward",
        "plots/reward_terms/forward",
        "plots/reward_terms/ctrl_cost",
        "plots/forward_speed",
        "plots/base_height",
        "plots/action/hip_4",
        "plots/torque/hip_4",
    ] {
        assert!(paths.contains(expected), "{expected} missing from {paths:?}");
    }
    assert_eq!(scene.len(), env.data().model().ngeom(), "every ant geom is drawable");
    for geom_path in &scene {
        assert!(paths.contains(geom_path), "{geom_path}");
    }

    // One frame per reset and per step: 2 episodes x (1 + 25).
    let frames = timeline_values(&chunks, "step");
    assert_eq!(frames, (0..52).collect::<BTreeSet<i64>>());
    assert_eq!(timeline_values(&chunks, "sim_time").len(), 52, "sim_time increases across episodes");

    let logged = transforms(&chunks, "world/torso");
    assert_eq!(logged.len(), 52);
    assert_eq!(poses.len(), 52);
    for frame in [0usize, 1, 13, 25, 26, 40, 51] {
        let (t, q) = logged[&(frame as i64)];
        let (p, wxyz) = poses[frame];
        for k in 0..3 {
            assert!((t[k] as f64 - p[k]).abs() < 1e-6, "frame {frame}: translation {t:?} vs xpos {p:?}");
        }
        // rerun stores x, y, z, w; MuJoCo w, x, y, z.
        let xyzw = [wxyz[1], wxyz[2], wxyz[3], wxyz[0]];
        for k in 0..4 {
            assert!((q[k] as f64 - xyzw[k]).abs() < 1e-6, "frame {frame}: quaternion {q:?} vs xquat {wxyz:?}");
        }
    }
}

#[test]
fn unfinished_recording_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("never.rrd");
    {
        let _recording = Recording::create(&path).unwrap();
    }
    assert!(!path.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "the partial file is removed");
}

#[test]
fn baseline_recording_carries_gait_phases_and_foot_targets() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("minitaur.rrd");
    let o = out.to_str().unwrap();
    let args = ["record", "--env", "minitaur", "--policy", "raibert", "--option", "max_episode_steps=60", "--out", o];
    let (ok, stdout, err) = locobench_with_path(&args, None);
    assert!(ok, "{err}");
    assert!(stdout.contains("61 frames"), "{stdout}");
    let chunks = read_chunks(&out);
    let paths = entity_paths(&chunks);
    for expected in [
        "world/base/chassis",
        "world/base",
        "plots/controller/stance/fl",
        "plots/controller/phase/br",
        "world/foot_targets",
        "plots/torque/motor_fl_outer",
        "plots/reward_terms/drift",
    ] {
        assert!(paths.contains(expected), "{expected} missing from {paths:?}");
    }
    assert_eq!(timeline_values(&chunks, "step").len(), 61);
}

#[test]
fn training_recording_has_curves_and_evaluation_rollouts_and_record_accepts_the_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let rrd = dir.path().join("training.rrd");
    let set = "warmup_steps=100,learning_starts=100,eval_every=150,eval_episodes=2,hidden=[16,16],batch_size=32";
    let (ok, _, err) = locobench_with_path(
        &[
            "train",
            "--env",
            "inverted-pendulum",
            "--algo",
            "sac",
            "--steps",
            "300",
            "--set",
            set,
            "--out",
            run.to_str().unwrap(),
            "--record",
            rrd.to_str().unwrap(),
            "--quiet",
        ],
        None,
    );
    assert!(ok, "{err}");
    let chunks = read_chunks(&rrd);
    let paths = entity_paths(&chunks);
    for expected in
        ["training/eval_mean", "training/episode_return", "training/critic_loss", "training/alpha", "world/pole"]
    {
        assert!(paths.contains(expected), "{expected} missing from {paths:?}");
    }
    // Two evaluations (steps 150 and 300), each followed by a recorded rollout tagged with it.
    let eval_steps: BTreeSet<i64> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string().trim_start_matches('/') == "training/eval_mean")
        .flat_map(|c| c.iter_indices(&"train_step".into()).map(|(t, _)| t.as_i64()).collect::<Vec<_>>())
        .collect();
    assert_eq!(eval_steps, BTreeSet::from([150, 300]));
    let rollout_steps: BTreeSet<i64> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string().trim_start_matches('/') == "world/pole")
        .flat_map(|c| c.iter_indices(&"train_step".into()).map(|(t, _)| t.as_i64()).collect::<Vec<_>>())
        .collect();
    assert_eq!(rollout_steps, BTreeSet::from([150, 300]));

    let again = dir.path().join("policy.rrd");
    let (ok, stdout, err) = locobench_with_path(
        &["record", "--policy", run.to_str().unwrap(), "--out", again.to_str().unwrap(), "--episodes", "2"],
        None,
    );
    assert!(ok, "{err}");
    assert!(stdout.contains("sac") && stdout.contains("episode 1"), "{stdout}");
    assert!(entity_paths(&read_chunks(&again)).contains("world/cart/cart"));
}

#[test]
fn record_errors_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.rrd");
    let o = out.to_str().unwrap();
    let (ok, _, err) = locobench_with_path(&["record", "--env", "ant", "--policy", "no-such-thing", "--out", o], None);
    assert!(!ok && err.contains("not raibert, random, zero"), "{err}");
    let (ok, _, err) =
        locobench_with_path(&["record", "--env", "half-cheetah", "--policy", "raibert", "--out", o], None);
    assert!(!ok && err.contains("minitaur and ant"), "{err}");
    assert!(!out.exists());

    // --spawn without a viewer: the recording is still written, and the message says how to get one.
    let args = ["record", "--env", "inverted-pendulum", "--policy", "zero", "--out", o, "--spawn"];
    let (ok, _, err) = locobench_with_path(&args, Some(""));
    assert!(!ok && err.contains("pip install rerun-sdk==0.36.3"), "{err}");
    assert!(out.exists());
}

#[test]
fn every_geom_type_becomes_its_rerun_primitive() {
    let xml = r#"<mujoco>
      <asset><mesh name="tetra" vertex="0 0 0  0.1 0 0  0 0.1 0  0 0 0.1"/></asset>
      <worldbody>
        <geom name="ground" type="plane" size="2 3 0.1" rgba="0.5 0.5 0.5 1"/>
        <body name="thing" pos="0 0 1">
          <freejoint/>
          <geom name="ball" type="sphere" size="0.1" rgba="1 0 0 1"/>
          <geom name="pill" type="capsule" size="0.05 0.2" pos="0.3 0 0" euler="30 60 0"/>
          <geom name="egg" type="ellipsoid" size="0.1 0.2 0.3" pos="0 0.3 0"/>
          <geom name="can" type="cylinder" size="0.1 0.2" pos="0 0 0.3"/>
          <geom name="crate" type="box" size="0.1 0.2 0.3" pos="0 -0.3 0" euler="0 0 45"/>
          <geom name="rock" type="mesh" mesh="tetra" pos="-0.3 0 0"/>
        </body>
      </worldbody>
    </mujoco>"#;
    let model = locobench::mujoco::Model::from_xml_str(xml).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("shapes.rrd");
    let recording = Recording::create(&path).unwrap();
    let written = locobench::record::log_scene(recording.stream(), &model).unwrap();
    recording.finish().unwrap();
    assert_eq!(written.len(), 7);

    let chunks = read_chunks(&path);
    // The archetype each entity was logged with, by its components' archetype names.
    let archetype_of = |entity: &str| -> BTreeSet<String> {
        chunks
            .iter()
            .filter(|c| c.entity_path().to_string().trim_start_matches('/') == entity)
            .flat_map(|c| {
                c.component_descriptors()
                    .filter_map(|d| d.archetype.map(|a| a.short_name().to_string()))
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    for (entity, archetype) in [
        ("world/ground", "Mesh3D"),
        ("world/thing/ball", "Ellipsoids3D"),
        ("world/thing/pill", "Capsules3D"),
        ("world/thing/egg", "Ellipsoids3D"),
        ("world/thing/can", "Cylinders3D"),
        ("world/thing/crate", "Boxes3D"),
        ("world/thing/rock", "Mesh3D"),
    ] {
        let found = archetype_of(entity);
        assert!(found.contains(archetype), "{entity}: {found:?}");
        assert!(chunks
            .iter()
            .filter(|c| c.entity_path().to_string().trim_start_matches('/') == entity)
            .all(|c| c.is_static()));
    }

    // The capsule's end caps, rebuilt from what was logged (rerun: from the translation along
    // +z for `length`), sit where MuJoCo puts them (centre +- half-length along the geom's z).
    let pill =
        chunks.iter().find(|c| c.entity_path().to_string().trim_start_matches('/') == "world/thing/pill").unwrap();
    let first = |d: rerun::ComponentDescriptor| d.component;
    let t: [f32; 3] = pill
        .iter_component::<rerun::components::Translation3D>(first(rerun::Capsules3D::descriptor_translations()))
        .next()
        .unwrap()[0]
        .0
        .into();
    let q: [f32; 4] = pill
        .iter_component::<rerun::components::RotationQuat>(first(rerun::Capsules3D::descriptor_quaternions()))
        .next()
        .unwrap()[0]
        .0
        .into();
    let len: f32 = pill
        .iter_component::<rerun::components::Length>(first(rerun::Capsules3D::descriptor_lengths()))
        .next()
        .unwrap()[0]
        .0
         .0;
    let rot = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[3], q[0], q[1], q[2]));
    let start = nalgebra::Vector3::new(t[0], t[1], t[2]);
    let end = start + rot * nalgebra::Vector3::new(0.0, 0.0, len);
    let g = model.geom_id("pill").unwrap();
    let (p, gq) = (&model.geom_pos()[3 * g..3 * g + 3], &model.geom_quat()[4 * g..4 * g + 4]);
    let grot = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(gq[0], gq[1], gq[2], gq[3]));
    let axis = grot * nalgebra::Vector3::new(0.0, 0.0, 0.2);
    let centre = nalgebra::Vector3::new(p[0], p[1], p[2]);
    for (logged, expected) in [(start, centre - axis), (end, centre + axis)] {
        assert!((logged.cast::<f64>() - expected).norm() < 1e-6, "{logged:?} vs {expected:?}");
    }
}
