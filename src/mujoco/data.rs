//! `Data`: one simulation state of a [`Model`]. One `Data` per thread; many may share a model.
use std::ptr::NonNull;
use std::sync::Arc;

use super::error::{check, install_handlers, MjError, MjResult};
use super::model::Model;
use super::sys;

/// Counters of MuJoCo's numerical-instability warnings (bad qpos, qvel, qacc). MuJoCo resets the
/// state silently when these fire; comparing counts before and after a step reveals it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct InstabilityCounts {
    /// Times MuJoCo found a non-finite or huge position.
    pub bad_qpos: i32,
    /// Times MuJoCo found a non-finite or huge velocity.
    pub bad_qvel: i32,
    /// Times MuJoCo found a non-finite or huge acceleration.
    pub bad_qacc: i32,
}

impl InstabilityCounts {
    /// All three counters summed.
    pub fn total(&self) -> i64 {
        self.bad_qpos as i64 + self.bad_qvel as i64 + self.bad_qacc as i64
    }
}

/// One active contact, as MuJoCo reports it.
#[derive(Debug, Clone, Copy)]
pub struct Contact {
    /// The first geom in contact.
    pub geom1: usize,
    /// The second geom in contact.
    pub geom2: usize,
    /// The contact point, world coordinates.
    pub pos: [f64; 3],
    /// Contact frame, rows: normal, tangent 1, tangent 2 (world coordinates).
    pub frame: [f64; 9],
    /// Signed distance between the geoms (negative when they penetrate).
    pub dist: f64,
    /// Force in the contact frame (normal, tangent 1, tangent 2).
    pub force: [f64; 3],
}

/// A simulation state (`mjData`) of one model: positions, velocities, controls and everything derived.
pub struct Data {
    ptr: NonNull<sys::mjData>,
    model: Arc<Model>,
}

// SAFETY: an mjData is owned memory; moving it to another thread is fine. It is not `Sync`.
unsafe impl Send for Data {}

macro_rules! field_slices {
    ($( $(#[$doc:meta])* $name:ident, $name_mut:ident, $field:ident, $len:expr; )*) => {
        $(
            $(#[$doc])*
            pub fn $name(&self) -> &[f64] {
                let n = { let m: &Model = &self.model; $len(m) };
                if n == 0 { return &[]; }
                // SAFETY: MuJoCo allocated this field with `n` entries for this state's model (n > 0 here);
                // the slice borrows `self`, so the state outlives it.
                unsafe { std::slice::from_raw_parts(self.raw().$field, n) }
            }
            $(#[$doc])*
            pub fn $name_mut(&mut self) -> &mut [f64] {
                let n = { let m: &Model = &self.model; $len(m) };
                if n == 0 { return &mut []; }
                // SAFETY: MuJoCo allocated this field with `n` entries for this state's model (n > 0 here);
                // `&mut self` makes the slice the only access.
                unsafe { std::slice::from_raw_parts_mut(self.ptr.as_mut().$field, n) }
            }
        )*
    };
}

impl Data {
    /// A fresh state of `model` at its initial configuration.
    pub fn new(model: &Arc<Model>) -> MjResult<Data> {
        install_handlers();
        let mut out: *mut sys::mjData = std::ptr::null_mut();
        // SAFETY: `model` is a live compiled model and `out` a valid place for the shim to write the new
        // state's pointer.
        check(unsafe { sys::lb_make_data(model.as_ptr(), &mut out) })?;
        let ptr = NonNull::new(out).ok_or_else(|| MjError::Engine("mj_makeData returned NULL".into()))?;
        Ok(Data { ptr, model: Arc::clone(model) })
    }

    /// The model this state belongs to.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// The raw pointer, for calling MuJoCo functions this layer does not wrap. Errors raised by
    /// such calls are not caught; the data stays owned by `self`.
    pub fn as_raw_mut(&mut self) -> *mut sys::mjData {
        self.ptr.as_ptr()
    }

    /// The state's pointer for MuJoCo calls that take `mjData*` but only read it
    /// (`mjv_updateScene`, which builds a scene from the positions).
    pub(crate) fn as_ptr_for_reading(&self) -> *mut sys::mjData {
        self.ptr.as_ptr()
    }

    fn raw(&self) -> &sys::mjData {
        // SAFETY: `ptr` came from mj_makeData, is non-null and stays valid until `drop`; a shared borrow only
        // reads.
        unsafe { self.ptr.as_ref() }
    }

    /// Advances the simulation by one timestep (`mj_step`).
    pub fn step(&mut self) -> MjResult<()> {
        // SAFETY: both pointers are live (the `Arc` keeps the model alive as long as this state) and `&mut
        // self` makes this the only access to the state.
        check(unsafe { sys::lb_step(self.model.as_ptr(), self.ptr.as_ptr()) })
    }

    /// Recomputes every derived quantity for the current state without integrating.
    pub fn forward(&mut self) -> MjResult<()> {
        // SAFETY: both pointers are live (the `Arc` keeps the model alive as long as this state) and `&mut
        // self` makes this the only access to the state.
        check(unsafe { sys::lb_forward(self.model.as_ptr(), self.ptr.as_ptr()) })
    }

    /// Fills `cfrc_ext`, `cacc` and `cfrc_int`; call after `step` when contact forces are needed.
    pub fn rne_post_constraint(&mut self) -> MjResult<()> {
        // SAFETY: both pointers are live (the `Arc` keeps the model alive as long as this state) and `&mut
        // self` makes this the only access to the state.
        check(unsafe { sys::lb_rne_post_constraint(self.model.as_ptr(), self.ptr.as_ptr()) })
    }

    /// Resets to the model's initial state (qpos0, zero velocity, time 0, warnings cleared).
    pub fn reset(&mut self) -> MjResult<()> {
        // SAFETY: both pointers are live (the `Arc` keeps the model alive as long as this state) and `&mut
        // self` makes this the only access to the state.
        check(unsafe { sys::lb_reset_data(self.model.as_ptr(), self.ptr.as_ptr()) })
    }

    /// Simulated time in seconds.
    pub fn time(&self) -> f64 {
        self.raw().time
    }

    /// MuJoCo's instability warning counters so far.
    pub fn instability_counts(&self) -> InstabilityCounts {
        let w = &self.raw().warning;
        InstabilityCounts {
            bad_qpos: w[sys::mjtWarning__mjWARN_BADQPOS as usize].number,
            bad_qvel: w[sys::mjtWarning__mjWARN_BADQVEL as usize].number,
            bad_qacc: w[sys::mjtWarning__mjWARN_BADQACC as usize].number,
        }
    }

    /// Number of times each of MuJoCo's warnings fired since the last reset.
    pub fn warning_counts(&self) -> [i32; sys::mjtWarning__mjNWARNING as usize] {
        let mut out = [0; sys::mjtWarning__mjNWARNING as usize];
        for (o, w) in out.iter_mut().zip(self.raw().warning.iter()) {
            *o = w.number;
        }
        out
    }

    field_slices! {
        /// Generalised positions (nq).
        qpos, qpos_mut, qpos, |m: &Model| m.nq();
        /// Generalised velocities (nv).
        qvel, qvel_mut, qvel, |m: &Model| m.nv();
        /// Generalised accelerations (nv).
        qacc, qacc_mut, qacc, |m: &Model| m.nv();
        /// Actuator controls (nu).
        ctrl, ctrl_mut, ctrl, |m: &Model| m.nu();
        /// Applied generalised forces (nv).
        qfrc_applied, qfrc_applied_mut, qfrc_applied, |m: &Model| m.nv();
        /// Actuator forces in joint space (nv).
        qfrc_actuator, qfrc_actuator_mut, qfrc_actuator, |m: &Model| m.nv();
        /// Scalar actuator forces (nu).
        actuator_force, actuator_force_mut, actuator_force, |m: &Model| m.nu();
        /// Body frame positions (nbody x 3).
        xpos, xpos_mut, xpos, |m: &Model| 3 * m.nbody();
        /// Body orientations as quaternions, MuJoCo order w, x, y, z (nbody x 4).
        xquat, xquat_mut, xquat, |m: &Model| 4 * m.nbody();
        /// Body orientations as row-major rotation matrices (nbody x 9).
        xmat, xmat_mut, xmat, |m: &Model| 9 * m.nbody();
        /// Body centre-of-mass positions (nbody x 3).
        xipos, xipos_mut, xipos, |m: &Model| 3 * m.nbody();
        /// Geom positions (ngeom x 3).
        geom_xpos, geom_xpos_mut, geom_xpos, |m: &Model| 3 * m.ngeom();
        /// Geom orientations (ngeom x 9).
        geom_xmat, geom_xmat_mut, geom_xmat, |m: &Model| 9 * m.ngeom();
        /// Joint anchor points in world coordinates (njnt x 3).
        xanchor, xanchor_mut, xanchor, |m: &Model| 3 * m.njnt();
        /// Joint axes in world coordinates (njnt x 3).
        xaxis, xaxis_mut, xaxis, |m: &Model| 3 * m.njnt();
        /// Site positions (nsite x 3).
        site_xpos, site_xpos_mut, site_xpos, |m: &Model| 3 * m.nsite();
        /// Site orientations (nsite x 9).
        site_xmat, site_xmat_mut, site_xmat, |m: &Model| 9 * m.nsite();
        /// Composite inertia in the centre-of-mass frame (nbody x 10).
        cinert, cinert_mut, cinert, |m: &Model| 10 * m.nbody();
        /// Centre-of-mass based velocities, rotation first (nbody x 6).
        cvel, cvel_mut, cvel, |m: &Model| 6 * m.nbody();
        /// External contact forces per body, torque first (nbody x 6); needs `rne_post_constraint`.
        cfrc_ext, cfrc_ext_mut, cfrc_ext, |m: &Model| 6 * m.nbody();
        /// Sensor readings (nsensordata).
        sensordata, sensordata_mut, sensordata, |m: &Model| m.nsensordata();
    }

    /// Sets qpos and qvel together, checking lengths, then runs `forward`.
    pub fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> MjResult<()> {
        let (nq, nv) = (self.model.nq(), self.model.nv());
        if qpos.len() != nq {
            return Err(MjError::BadLength { what: "qpos", expected: nq, got: qpos.len() });
        }
        if qvel.len() != nv {
            return Err(MjError::BadLength { what: "qvel", expected: nv, got: qvel.len() });
        }
        self.qpos_mut().copy_from_slice(qpos);
        self.qvel_mut().copy_from_slice(qvel);
        self.forward()
    }

    /// Copies `ctrl` after checking its length.
    pub fn set_ctrl(&mut self, ctrl: &[f64]) -> MjResult<()> {
        let nu = self.model.nu();
        if ctrl.len() != nu {
            return Err(MjError::BadLength { what: "ctrl", expected: nu, got: ctrl.len() });
        }
        self.ctrl_mut().copy_from_slice(ctrl);
        Ok(())
    }

    /// Translational and rotational Jacobians (3 x nv each, row-major) of a site.
    pub fn jacobian_site(&mut self, site: usize) -> MjResult<(Vec<f64>, Vec<f64>)> {
        let count = self.model.nsite();
        if site >= count {
            return Err(MjError::BadIndex { kind: "site", index: site, count });
        }
        let nv = self.model.nv();
        let (mut jacp, mut jacr) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
        // SAFETY: `jacp` and `jacr` hold the 3 x nv doubles mj_jacSite writes, and `site` was checked against
        // the model above.
        check(unsafe {
            sys::lb_jac_site(self.model.as_ptr(), self.ptr.as_ptr(), jacp.as_mut_ptr(), jacr.as_mut_ptr(), site as i32)
        })?;
        Ok((jacp, jacr))
    }

    /// Translational and rotational Jacobians (3 x nv each, row-major) of a body's frame origin.
    pub fn jacobian_body(&mut self, body: usize) -> MjResult<(Vec<f64>, Vec<f64>)> {
        let count = self.model.nbody();
        if body >= count {
            return Err(MjError::BadIndex { kind: "body", index: body, count });
        }
        let nv = self.model.nv();
        let (mut jacp, mut jacr) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
        // SAFETY: `jacp` and `jacr` hold the 3 x nv doubles mj_jacBody writes, and `body` was checked against
        // the model above.
        check(unsafe {
            sys::lb_jac_body(self.model.as_ptr(), self.ptr.as_ptr(), jacp.as_mut_ptr(), jacr.as_mut_ptr(), body as i32)
        })?;
        Ok((jacp, jacr))
    }

    /// The active contacts with their forces in the contact frame.
    pub fn contacts(&self) -> Vec<Contact> {
        let n = self.raw().ncon.max(0) as usize;
        // SAFETY: `contact` holds `ncon` entries (n > 0 here), valid until the next step, which needs `&mut
        // self`.
        let list = if n == 0 { &[][..] } else { unsafe { std::slice::from_raw_parts(self.raw().contact, n) } };
        list.iter()
            .enumerate()
            .map(|(i, c)| {
                let mut f = [0.0f64; 6];
                // SAFETY: `i < ncon` and `f` has the six doubles mj_contactForce writes.
                unsafe { sys::mj_contactForce(self.model.as_ptr(), self.ptr.as_ptr(), i as i32, f.as_mut_ptr()) };
                Contact {
                    geom1: c.geom1 as usize,
                    geom2: c.geom2 as usize,
                    pos: c.pos,
                    frame: c.frame,
                    dist: c.dist,
                    force: [f[0], f[1], f[2]],
                }
            })
            .collect()
    }
}

impl Drop for Data {
    fn drop(&mut self) {
        // SAFETY: `ptr` came from mj_makeData and is freed exactly once, here.
        unsafe { sys::mj_deleteData(self.ptr.as_ptr()) };
    }
}

impl std::fmt::Debug for Data {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Data(time={}, model={:?})", self.time(), self.model)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fatal_engine_error_becomes_err_and_process_survives() {
        let xml =
            r#"<mujoco><worldbody><body><freejoint/><geom type="sphere" size="0.1"/></body></worldbody></mujoco>"#;
        let mut model = Model::from_xml_str(xml).unwrap();
        // An integrator id MuJoCo does not know: mj_step calls mju_error("Invalid integrator"),
        // whose default handler would wait on stdin and then exit the process.
        // SAFETY: nothing else holds the model yet, and `opt` is plain data MuJoCo reads per step.
        unsafe { (*(model.as_ptr() as *mut sys::mjModel)).opt.integrator = 77 };
        let _ = &mut model;
        let model = Arc::new(model);
        let mut d = Data::new(&model).unwrap();
        match d.step() {
            Err(MjError::Engine(msg)) => assert!(msg.contains("integrator"), "{msg}"),
            other => panic!("expected an engine error, got {other:?}"),
        }
        d.reset().unwrap();
        assert!(d.step().is_err(), "the same call fails the same way again");
        d.forward().unwrap();
    }
}
