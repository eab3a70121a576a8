//! The safe MuJoCo layer: loading, errors, named access, stepping, Jacobians, threads.
use std::sync::Arc;

use locobench::mujoco::{take_warnings, version, Data, MjError, Model, ObjKind};

const MODELS: [&str; 5] = ["half_cheetah", "ant", "humanoid", "inverted_pendulum", "minitaur"];

/// Size of MuJoCo's default log file in the working directory (None when absent), to check that
/// nothing our code does appends to it.
fn mujoco_log_size() -> Option<u64> {
    std::fs::metadata("MUJOCO_LOG.TXT").ok().map(|m| m.len())
}

fn model_path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models").join(format!("{name}.xml"))
}

#[test]
fn library_is_2_2_2() {
    assert_eq!(version(), 222);
}

#[test]
fn every_shipped_model_loads_from_path_and_from_string() {
    for name in MODELS {
        let from_path = Model::from_xml_path(model_path(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let text = std::fs::read_to_string(model_path(name)).unwrap();
        let from_str = Model::from_xml_str(&text).unwrap();
        assert_eq!(from_path.nq(), from_str.nq(), "{name}");
        assert_eq!(from_path.qpos0(), from_str.qpos0(), "{name}");
    }
}

#[test]
fn model_sizes_match_the_standard_models() {
    let sizes = |n: &str| {
        let m = Model::from_xml_path(model_path(n)).unwrap();
        (m.nq(), m.nv(), m.nu(), m.nbody())
    };
    assert_eq!(sizes("half_cheetah"), (9, 9, 6, 8));
    assert_eq!(sizes("ant"), (15, 14, 8, 14));
    assert_eq!(sizes("humanoid"), (24, 23, 17, 14));
    assert_eq!(sizes("inverted_pendulum"), (2, 2, 1, 3));
    let m = Model::from_xml_path(model_path("minitaur")).unwrap();
    assert_eq!(m.nu(), 8);
    assert_eq!(m.neq(), 4);
    let total: f64 = m.body_mass().iter().sum();
    assert!((total - 6.0).abs() < 1e-9, "minitaur mass {total}");
}

#[test]
fn half_cheetah_total_mass_is_14kg() {
    let m = Model::from_xml_path(model_path("half_cheetah")).unwrap();
    let total: f64 = m.body_mass().iter().sum();
    assert!((total - 14.0).abs() < 1e-9, "{total}");
}

#[test]
fn malformed_xml_is_an_error_with_mujocos_message() {
    let log_before = mujoco_log_size();
    let err =
        Model::from_xml_str("<mujoco><worldbody><geom type='spherez' size='1'/></worldbody></mujoco>").unwrap_err();
    match &err {
        MjError::Load(msg) => assert!(msg.contains("spherez"), "{msg}"),
        other => panic!("unexpected {other:?}"),
    }
    let err = Model::from_xml_str("<mujoco><worldbody>").unwrap_err();
    assert!(matches!(err, MjError::Load(ref m) if m.to_lowercase().contains("xml")), "{err}");
    let err = Model::from_xml_path("/nonexistent/model.xml").unwrap_err();
    assert!(matches!(err, MjError::Load(_)), "{err}");
    assert_eq!(mujoco_log_size(), log_before, "MuJoCo wrote to MUJOCO_LOG.TXT");
}

#[test]
fn names_map_to_ids_and_unknown_names_are_errors() {
    let m = Model::from_xml_path(model_path("ant")).unwrap();
    assert_eq!(m.body_id("torso").unwrap(), 1);
    assert_eq!(m.id(ObjKind::Body, "world").unwrap(), 0);
    let hip4 = m.joint_id("hip_4").unwrap();
    assert_eq!(m.name(ObjKind::Joint, hip4).unwrap().as_deref(), Some("hip_4"));
    assert_eq!(m.actuator_id("hip_4").unwrap(), 0);
    assert!(m.geom_id("floor").is_ok());
    assert!(matches!(m.body_id("tail"), Err(MjError::UnknownName { kind: "body", .. })));
    assert!(m.site_id("nope").is_err());
    assert!(matches!(m.name(ObjKind::Body, 999), Err(MjError::BadIndex { .. })));
    let mt = Model::from_xml_path(model_path("minitaur")).unwrap();
    assert!(mt.site_id("foot_fl").is_ok());
}

#[test]
fn data_steps_resets_and_checks_lengths() {
    let m = Arc::new(Model::from_xml_path(model_path("half_cheetah")).unwrap());
    let mut d = Data::new(&m).unwrap();
    assert_eq!(d.qpos().len(), 9);
    d.set_ctrl(&[0.5; 6]).unwrap();
    for _ in 0..10 {
        d.step().unwrap();
    }
    assert!((d.time() - 0.1).abs() < 1e-12);
    assert!(d.qpos().iter().zip(m.qpos0()).any(|(a, b)| a != b));
    assert!(matches!(d.set_ctrl(&[0.0; 5]), Err(MjError::BadLength { expected: 6, got: 5, .. })));
    assert!(d.set_state(&[0.0; 3], &[0.0; 9]).is_err());
    d.reset().unwrap();
    assert_eq!(d.time(), 0.0);
    assert_eq!(d.qpos(), m.qpos0());
}

#[test]
fn cfrc_ext_needs_rne_post_constraint() {
    let m = Arc::new(Model::from_xml_path(model_path("ant")).unwrap());
    let mut d = Data::new(&m).unwrap();
    for _ in 0..100 {
        d.step().unwrap();
    }
    assert!(d.cfrc_ext().iter().all(|&f| f == 0.0));
    d.rne_post_constraint().unwrap();
    assert!(d.cfrc_ext().iter().any(|&f| f != 0.0), "the ant should touch the floor after 1 s");
    assert!(!d.contacts().is_empty());
}

#[test]
fn site_jacobian_predicts_site_motion() {
    let m = Arc::new(Model::from_xml_path(model_path("minitaur")).unwrap());
    let mut d = Data::new(&m).unwrap();
    d.forward().unwrap();
    let site = m.site_id("foot_fl").unwrap();
    let (jacp, _) = d.jacobian_site(site).unwrap();
    let before: Vec<f64> = d.site_xpos()[3 * site..3 * site + 3].to_vec();
    // Perturb the outer motor of the front-left leg by a small angle.
    let j = m.joint_id("motor_fl_outer").unwrap();
    let (qa, va) = (m.joint_qpos_adr(j), m.joint_dof_adr(j));
    let eps = 1e-6;
    d.qpos_mut()[qa] += eps;
    d.forward().unwrap();
    let after = &d.site_xpos()[3 * site..3 * site + 3];
    for k in 0..3 {
        let predicted = jacp[k * m.nv() + va] * eps;
        assert!((after[k] - before[k] - predicted).abs() < 1e-9, "axis {k}");
    }
    assert!(d.jacobian_site(999).is_err());
    assert!(d.jacobian_body(999).is_err());
    let (jb, _) = d.jacobian_body(1).unwrap();
    assert_eq!(jb.len(), 3 * m.nv());
}

#[test]
fn one_model_many_threads() {
    let m = Arc::new(Model::from_xml_path(model_path("half_cheetah")).unwrap());
    let run = |m: Arc<Model>| {
        std::thread::spawn(move || {
            let mut d = Data::new(&m).unwrap();
            d.set_ctrl(&[0.3, -0.2, 0.1, 0.4, -0.5, 0.6]).unwrap();
            for _ in 0..200 {
                d.step().unwrap();
            }
            d.qpos().to_vec()
        })
    };
    let a = run(Arc::clone(&m));
    let b = run(Arc::clone(&m));
    assert_eq!(a.join().unwrap(), b.join().unwrap());
}

#[test]
fn instability_is_reported_not_hidden() {
    let log_before = mujoco_log_size();
    let m = Arc::new(Model::from_xml_path(model_path("half_cheetah")).unwrap());
    let mut d = Data::new(&m).unwrap();
    take_warnings();
    d.qvel_mut()[3] = f64::NAN;
    d.step().unwrap();
    // MuJoCo resets the state silently; the counters and the warning text say it happened.
    assert!(d.instability_counts().total() > 0);
    let warnings = take_warnings();
    assert!(!warnings.is_empty(), "warning should reach Rust");
    assert_eq!(mujoco_log_size(), log_before, "MuJoCo wrote to MUJOCO_LOG.TXT");
}
