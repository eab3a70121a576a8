//! `Model`: a compiled, read-only `mjModel`, shareable between threads.
use std::ffi::{CStr, CString};
use std::os::raw::c_char;
use std::path::Path;
use std::ptr::NonNull;

use super::error::{check, install_handlers, MjError, MjResult};
use super::sys;

/// The kinds of named model elements that can be looked up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjKind {
    /// A body.
    Body,
    /// A joint.
    Joint,
    /// A geom (collision or visual shape).
    Geom,
    /// A site (a named frame on a body).
    Site,
    /// An actuator.
    Actuator,
    /// A sensor.
    Sensor,
    /// A camera.
    Camera,
}

impl ObjKind {
    fn raw(self) -> i32 {
        (match self {
            ObjKind::Body => sys::mjtObj__mjOBJ_BODY,
            ObjKind::Joint => sys::mjtObj__mjOBJ_JOINT,
            ObjKind::Geom => sys::mjtObj__mjOBJ_GEOM,
            ObjKind::Site => sys::mjtObj__mjOBJ_SITE,
            ObjKind::Actuator => sys::mjtObj__mjOBJ_ACTUATOR,
            ObjKind::Sensor => sys::mjtObj__mjOBJ_SENSOR,
            ObjKind::Camera => sys::mjtObj__mjOBJ_CAMERA,
        }) as i32
    }

    /// The kind's name in messages (`body`, `joint`, ...).
    pub fn label(self) -> &'static str {
        match self {
            ObjKind::Body => "body",
            ObjKind::Joint => "joint",
            ObjKind::Geom => "geom",
            ObjKind::Site => "site",
            ObjKind::Actuator => "actuator",
            ObjKind::Sensor => "sensor",
            ObjKind::Camera => "camera",
        }
    }
}

/// A mesh's vertices (x y z each) and triangles (three vertex indices each).
pub type MeshData = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// A compiled MuJoCo model (`mjModel`), shared read-only between states.
pub struct Model {
    ptr: NonNull<sys::mjModel>,
}

// SAFETY: after compilation an mjModel is plain memory that MuJoCo only reads during simulation;
// MuJoCo documents sharing one model between threads that each own an mjData.
unsafe impl Send for Model {}
// SAFETY: as for `Send`: a shared `Model` is only read.
unsafe impl Sync for Model {}

const ERR_LEN: usize = 1000;

fn error_text(buf: &[c_char]) -> String {
    let bytes: Vec<u8> = buf.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    String::from_utf8_lossy(&bytes).trim().to_string()
}

impl Model {
    /// Loads and compiles an MJCF file.
    pub fn from_xml_path(path: impl AsRef<Path>) -> MjResult<Model> {
        install_handlers();
        let path = path.as_ref();
        let c_path = CString::new(path.to_string_lossy().as_bytes())
            .map_err(|_| MjError::Load(format!("path {} contains a NUL byte", path.display())))?;
        let mut err = [0 as c_char; ERR_LEN];
        let mut out: *mut sys::mjModel = std::ptr::null_mut();
        // SAFETY: both strings are NUL-terminated, `err` has the ERR_LEN bytes passed, and `out` is a valid
        // place for the model's pointer.
        let rc = unsafe { sys::lb_load_xml_file(c_path.as_ptr(), err.as_mut_ptr(), ERR_LEN as i32, &mut out) };
        Self::finish_load(rc, out, &err, &path.display().to_string())
    }

    /// Compiles an MJCF document held in memory (through MuJoCo's virtual file system).
    pub fn from_xml_str(xml: &str) -> MjResult<Model> {
        install_handlers();
        if xml.contains('\0') {
            return Err(MjError::Load("model text contains a NUL byte".into()));
        }
        let len = i32::try_from(xml.len()).map_err(|_| MjError::Load("model text too large".into()))?;
        let name = CString::new("locobench_model.xml").unwrap();
        let mut err = [0 as c_char; ERR_LEN];
        let mut out: *mut sys::mjModel = std::ptr::null_mut();
        // SAFETY: both strings are NUL-terminated (checked above), `len` is the text's length, `err` has the
        // ERR_LEN bytes passed, and `out` is a valid place for the model's pointer.
        let rc = unsafe {
            sys::lb_load_xml_string(
                name.as_ptr(),
                xml.as_ptr() as *const c_char,
                len,
                err.as_mut_ptr(),
                ERR_LEN as i32,
                &mut out,
            )
        };
        Self::finish_load(rc, out, &err, "<string>")
    }

    fn finish_load(rc: i32, out: *mut sys::mjModel, err: &[c_char], source: &str) -> MjResult<Model> {
        if rc < 0 {
            return Err(MjError::Load(format!("{source}: {}", super::error::last_engine_error())));
        }
        match NonNull::new(out) {
            Some(ptr) if rc == 0 => Ok(Model { ptr }),
            _ => {
                let msg = error_text(err);
                Err(MjError::Load(format!("{source}: {}", if msg.is_empty() { "unknown error" } else { &msg })))
            }
        }
    }

    /// A deep copy whose parameters (masses, friction) may then be changed.
    pub fn try_clone(&self) -> MjResult<Model> {
        let mut out: *mut sys::mjModel = std::ptr::null_mut();
        // SAFETY: `self.ptr` is a live model and `out` a valid place for the copy's pointer.
        check(unsafe { sys::lb_copy_model(self.ptr.as_ptr(), &mut out) })?;
        NonNull::new(out).map(|ptr| Model { ptr }).ok_or_else(|| MjError::Engine("mj_copyModel returned NULL".into()))
    }

    /// Sets the offscreen framebuffer's size (`<visual><global offwidth offheight>`), which
    /// MuJoCo's renderer reads when its context is made. For a renderer's own copy of a model.
    pub(crate) fn set_offscreen_size(&mut self, width: usize, height: usize) {
        // SAFETY: `&mut self` is the only access to this model; two plain ints are written.
        unsafe {
            let global = &mut self.ptr.as_mut().vis.global;
            global.offwidth = width as i32;
            global.offheight = height as i32;
        }
    }

    /// Body `body`'s position in its parent's frame at the initial configuration (`body_pos`).
    pub fn body_pos(&self, body: usize) -> [f64; 3] {
        assert!(body < self.nbody(), "body {body} out of range");
        // SAFETY: MuJoCo allocates body_pos with 3 entries per body; `body` is in range.
        let p = unsafe { std::slice::from_raw_parts(self.raw().body_pos.add(3 * body), 3) };
        [p[0], p[1], p[2]]
    }

    /// Each geom's bounding-sphere radius (`geom_rbound`).
    pub fn geom_rbound(&self) -> &[f64] {
        // SAFETY: MuJoCo allocates geom_rbound with one entry per geom.
        unsafe { std::slice::from_raw_parts(self.raw().geom_rbound, self.ngeom()) }
    }

    /// Sets the renderer's quality settings (`<visual><quality shadowsize offsamples>`): the
    /// shadow map's side in texels and the offscreen buffer's multisamples.
    pub(crate) fn set_render_quality(&mut self, shadowsize: usize, offsamples: usize) {
        // SAFETY: `&mut self` is the only access to this model; two plain ints are written.
        unsafe {
            let quality = &mut self.ptr.as_mut().vis.quality;
            quality.shadowsize = shadowsize as i32;
            quality.offsamples = offsamples as i32;
        }
    }

    /// The model's extent (`stat.extent`): the size of its bounding box, for camera distances.
    pub fn extent(&self) -> f64 {
        self.raw().stat.extent
    }

    pub(crate) fn raw(&self) -> &sys::mjModel {
        // SAFETY: `ptr` came from MuJoCo's compiler, is non-null and stays valid until `drop`; a shared
        // borrow only reads.
        unsafe { self.ptr.as_ref() }
    }

    pub(crate) fn as_ptr(&self) -> *const sys::mjModel {
        self.ptr.as_ptr()
    }

    /// The raw pointer, for calling MuJoCo functions this layer does not wrap (benchmarks use it
    /// to time bare `mj_step`). The model stays owned by `self`.
    pub fn as_raw(&self) -> *const sys::mjModel {
        self.ptr.as_ptr()
    }

    /// Number of cameras the model defines (`ncam`).
    pub fn ncam(&self) -> usize {
        self.raw().ncam as usize
    }

    /// Number of position coordinates (`nq`).
    pub fn nq(&self) -> usize {
        self.raw().nq as usize
    }
    /// Number of degrees of freedom (`nv`).
    pub fn nv(&self) -> usize {
        self.raw().nv as usize
    }
    /// Whether the model starts with one free joint (7 position and 6 velocity coordinates ahead
    /// of the rest): a floating base that can be pushed.
    pub fn has_floating_base(&self) -> bool {
        self.nq() == self.nv() + 1 && self.nv() >= 6
    }
    /// Number of actuators (`nu`).
    pub fn nu(&self) -> usize {
        self.raw().nu as usize
    }
    /// Number of bodies, the world body included.
    pub fn nbody(&self) -> usize {
        self.raw().nbody as usize
    }
    /// Number of joints.
    pub fn njnt(&self) -> usize {
        self.raw().njnt as usize
    }
    /// Number of geoms.
    pub fn ngeom(&self) -> usize {
        self.raw().ngeom as usize
    }
    /// Number of sites.
    pub fn nsite(&self) -> usize {
        self.raw().nsite as usize
    }
    /// Length of the sensor data array.
    pub fn nsensordata(&self) -> usize {
        self.raw().nsensordata as usize
    }
    /// Number of equality constraints.
    pub fn neq(&self) -> usize {
        self.raw().neq as usize
    }
    /// Simulation time step in seconds.
    pub fn timestep(&self) -> f64 {
        self.raw().opt.timestep
    }
    /// Gravity vector, world coordinates.
    pub fn gravity(&self) -> [f64; 3] {
        self.raw().opt.gravity
    }

    fn count(&self, kind: ObjKind) -> usize {
        match kind {
            ObjKind::Body => self.nbody(),
            ObjKind::Joint => self.njnt(),
            ObjKind::Geom => self.ngeom(),
            ObjKind::Site => self.nsite(),
            ObjKind::Actuator => self.nu(),
            ObjKind::Sensor => self.raw().nsensor as usize,
            ObjKind::Camera => self.ncam(),
        }
    }

    /// Name → index; an unknown name is an error.
    pub fn id(&self, kind: ObjKind, name: &str) -> MjResult<usize> {
        let unknown = || MjError::UnknownName { kind: kind.label(), name: name.to_string() };
        let c_name = CString::new(name).map_err(|_| unknown())?;
        // SAFETY: `c_name` is NUL-terminated and the model is live.
        let id = unsafe { sys::mj_name2id(self.as_ptr(), kind.raw(), c_name.as_ptr()) };
        if id < 0 {
            Err(unknown())
        } else {
            Ok(id as usize)
        }
    }

    /// Index → name (None for unnamed elements); an index out of range is an error.
    pub fn name(&self, kind: ObjKind, index: usize) -> MjResult<Option<String>> {
        let count = self.count(kind);
        if index >= count {
            return Err(MjError::BadIndex { kind: kind.label(), index, count });
        }
        // SAFETY: `index` is below the model's count of that kind (checked above).
        let p = unsafe { sys::mj_id2name(self.as_ptr(), kind.raw(), index as i32) };
        if p.is_null() {
            return Ok(None);
        }
        // SAFETY: mj_id2name returned a non-null, NUL-terminated name stored in the model, which outlives
        // this call.
        let s = unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned();
        Ok(if s.is_empty() { None } else { Some(s) })
    }

    /// The index of the body named `name`.
    pub fn body_id(&self, name: &str) -> MjResult<usize> {
        self.id(ObjKind::Body, name)
    }
    /// The index of the joint named `name`.
    pub fn joint_id(&self, name: &str) -> MjResult<usize> {
        self.id(ObjKind::Joint, name)
    }
    /// The index of the geom named `name`.
    pub fn geom_id(&self, name: &str) -> MjResult<usize> {
        self.id(ObjKind::Geom, name)
    }
    /// The index of the site named `name`.
    pub fn site_id(&self, name: &str) -> MjResult<usize> {
        self.id(ObjKind::Site, name)
    }
    /// The index of the actuator named `name`.
    pub fn actuator_id(&self, name: &str) -> MjResult<usize> {
        self.id(ObjKind::Actuator, name)
    }

    /// Address of a joint's first coordinate in qpos.
    pub fn joint_qpos_adr(&self, joint: usize) -> usize {
        self.slice_i32(self.raw().jnt_qposadr, self.njnt())[joint] as usize
    }
    /// Address of a joint's first degree of freedom in qvel.
    pub fn joint_dof_adr(&self, joint: usize) -> usize {
        self.slice_i32(self.raw().jnt_dofadr, self.njnt())[joint] as usize
    }

    /// Initial positions (`qpos0`), length `nq`.
    pub fn qpos0(&self) -> &[f64] {
        self.slice_f64(self.raw().qpos0, self.nq())
    }
    /// Mass of each body.
    pub fn body_mass(&self) -> &[f64] {
        self.slice_f64(self.raw().body_mass, self.nbody())
    }
    /// Each body's centre of mass in its own frame (`body_ipos`), `3 * nbody` values.
    pub fn body_ipos(&self) -> &[f64] {
        self.slice_f64(self.raw().body_ipos, 3 * self.nbody())
    }
    /// Whether `body` hangs from its parent by a free joint (six degrees of freedom), so it can
    /// turn about the vertical; planar models (a slide-slide-hinge root) cannot.
    pub fn body_is_free(&self, body: usize) -> bool {
        let r = self.raw();
        let (first, count) =
            (self.slice_i32(r.body_jntadr, self.nbody())[body], self.slice_i32(r.body_jntnum, self.nbody())[body]);
        let types = self.slice_i32(r.jnt_type, self.njnt());
        count > 0 && (first..first + count).any(|j| types[j as usize] == sys::mjtJoint__mjJNT_FREE as i32)
    }
    /// Parent body of each body (the world body is its own parent).
    pub fn body_parent(&self) -> &[i32] {
        self.slice_i32(self.raw().body_parentid, self.nbody())
    }
    /// Actuator control ranges as (low, high) pairs; `ctrl_limited` says which apply.
    pub fn actuator_ctrlrange(&self) -> &[f64] {
        self.slice_f64(self.raw().actuator_ctrlrange, 2 * self.nu())
    }
    /// Each actuator's transmission gear (`nu x 6`; a motor's torque is `gear[0] * ctrl`).
    pub fn actuator_gear(&self) -> &[f64] {
        self.slice_f64(self.raw().actuator_gear, 6 * self.nu())
    }
    /// Whether each actuator's control is clamped to its range.
    pub fn actuator_ctrllimited(&self) -> Vec<bool> {
        let r = self.raw();
        // SAFETY: MuJoCo allocates `nu` entries for this array.
        unsafe { std::slice::from_raw_parts(r.actuator_ctrllimited, self.nu()) }.iter().map(|&b| b != 0).collect()
    }
    /// What each actuator drives (`nu x 2`: object id, and a second id for some transmissions).
    pub fn actuator_trnid(&self) -> &[i32] {
        self.slice_i32(self.raw().actuator_trnid, 2 * self.nu())
    }
    /// Shape type of each geom (`mjtGeom`).
    pub fn geom_type(&self) -> &[i32] {
        self.slice_i32(self.raw().geom_type, self.ngeom())
    }
    /// Size parameters of each geom (`ngeom x 3`, meaning depends on the type).
    pub fn geom_size(&self) -> &[f64] {
        self.slice_f64(self.raw().geom_size, 3 * self.ngeom())
    }
    /// Colour of each geom, RGBA (`ngeom x 4`).
    pub fn geom_rgba(&self) -> &[f32] {
        let r = self.raw();
        // SAFETY: MuJoCo allocates `4 * ngeom` entries for this array.
        unsafe { std::slice::from_raw_parts(r.geom_rgba, 4 * self.ngeom()) }
    }
    /// The body each geom is attached to.
    pub fn geom_body(&self) -> &[i32] {
        self.slice_i32(self.raw().geom_bodyid, self.ngeom())
    }
    /// Sliding, torsional and rolling friction of each geom (`ngeom x 3`).
    pub fn geom_friction(&self) -> &[f64] {
        self.slice_f64(self.raw().geom_friction, 3 * self.ngeom())
    }
    /// Joint limits as (low, high) pairs (`njnt x 2`).
    pub fn jnt_range(&self) -> &[f64] {
        self.slice_f64(self.raw().jnt_range, 2 * self.njnt())
    }

    /// Geom position relative to its body (ngeom x 3).
    pub fn geom_pos(&self) -> &[f64] {
        self.slice_f64(self.raw().geom_pos, 3 * self.ngeom())
    }
    /// Geom orientation relative to its body, w x y z (ngeom x 4).
    pub fn geom_quat(&self) -> &[f64] {
        self.slice_f64(self.raw().geom_quat, 4 * self.ngeom())
    }
    /// Material of each geom, -1 for none.
    pub fn geom_matid(&self) -> &[i32] {
        self.slice_i32(self.raw().geom_matid, self.ngeom())
    }
    /// Mesh (or height field) of each geom, -1 for none.
    pub fn geom_dataid(&self) -> &[i32] {
        self.slice_i32(self.raw().geom_dataid, self.ngeom())
    }
    /// Colour of each material, RGBA (`nmat x 4`).
    pub fn mat_rgba(&self) -> &[f32] {
        let n = 4 * self.raw().nmat.max(0) as usize;
        if n == 0 {
            return &[];
        }
        // SAFETY: `mat_rgba` holds `4 * nmat` floats (n > 0 here).
        unsafe { std::slice::from_raw_parts(self.raw().mat_rgba, n) }
    }
    /// The colour a geom is drawn with: its material's when it has one, else its own.
    pub fn geom_color(&self, geom: usize) -> [f32; 4] {
        let mat = self.geom_matid()[geom];
        let rgba = if mat >= 0 { &self.mat_rgba()[4 * mat as usize..] } else { &self.geom_rgba()[4 * geom..] };
        [rgba[0], rgba[1], rgba[2], rgba[3]]
    }
    /// Number of meshes.
    pub fn nmesh(&self) -> usize {
        self.raw().nmesh.max(0) as usize
    }
    /// Vertices (x y z each) and triangles (three vertex indices each) of mesh `mesh`.
    pub fn mesh(&self, mesh: usize) -> MjResult<MeshData> {
        let count = self.nmesh();
        if mesh >= count {
            return Err(MjError::BadIndex { kind: "mesh", index: mesh, count });
        }
        let r = self.raw();
        // SAFETY: `mesh < nmesh` (checked above) and both arrays have `nmesh` entries.
        let at = |p: *const i32| unsafe { *p.add(mesh) }.max(0) as usize;
        let (vadr, vnum) = (at(r.mesh_vertadr), at(r.mesh_vertnum));
        let (fadr, fnum) = (at(r.mesh_faceadr), at(r.mesh_facenum));
        let verts = if vnum == 0 {
            &[][..]
        } else {
            // SAFETY: MuJoCo's own addresses: vertices `vadr..vadr + vnum` lie inside its vertex array (non-
            // empty here).
            unsafe { std::slice::from_raw_parts(r.mesh_vert.add(3 * vadr), 3 * vnum) }
        };
        let faces = if fnum == 0 {
            &[][..]
        } else {
            // SAFETY: MuJoCo's own addresses: faces `fadr..fadr + fnum` lie inside its face array (non-empty
            // here).
            unsafe { std::slice::from_raw_parts(r.mesh_face.add(3 * fadr), 3 * fnum) }
        };
        Ok((
            verts.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect(),
            faces.chunks_exact(3).map(|f| [f[0] as u32, f[1] as u32, f[2] as u32]).collect(),
        ))
    }

    /// Mutable parameters for domain randomisation. Needs exclusive access (a fresh
    /// [`Model::try_clone`]), so shared models can never change under a running simulation.
    pub fn body_mass_mut(&mut self) -> &mut [f64] {
        let n = self.nbody();
        // SAFETY: `body_mass` has `nbody` entries and `&mut self` makes the slice the only access.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_mut().body_mass, n) }
    }
    /// Friction of each geom, writable (e.g. to randomise it).
    pub fn geom_friction_mut(&mut self) -> &mut [f64] {
        let n = 3 * self.ngeom();
        // SAFETY: `geom_friction` has `3 * ngeom` entries and `&mut self` makes the slice the only access.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_mut().geom_friction, n) }
    }
    /// Moves `body`'s centre of mass by `offset` in its own frame (`body_ipos`). A body whose
    /// inertial frame the compiler found to coincide with its frame (`body_sameframe`) has its
    /// centre of mass taken from the body frame and its `body_ipos` ignored, so that flag is
    /// cleared too.
    pub fn shift_body_com(&mut self, body: usize, offset: [f64; 3]) {
        assert!(body < self.nbody(), "body {body} out of range");
        // SAFETY: `body_ipos` has `3 * nbody` entries and `body_sameframe` `nbody`; `body` is in
        // range and `&mut self` makes these the only accesses.
        unsafe {
            let raw = self.ptr.as_mut();
            let ipos = std::slice::from_raw_parts_mut(raw.body_ipos.add(3 * body), 3);
            for (p, o) in ipos.iter_mut().zip(offset) {
                *p += o;
            }
            *raw.body_sameframe.add(body) = 0;
        }
    }
    /// Whether each body's inertial frame coincides with its frame (`body_sameframe`).
    pub fn body_sameframe(&self) -> Vec<bool> {
        let r = self.raw();
        // SAFETY: `body_sameframe` has `nbody` entries.
        unsafe { std::slice::from_raw_parts(r.body_sameframe, self.nbody()) }.iter().map(|&b| b != 0).collect()
    }
    /// Each body's principal moments of inertia (`body_inertia`), writable.
    pub fn body_inertia_mut(&mut self) -> &mut [f64] {
        let n = 3 * self.nbody();
        // SAFETY: `body_inertia` has `3 * nbody` entries and `&mut self` makes the slice the only access.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_mut().body_inertia, n) }
    }
    /// Each actuator's gear (`nu x 6`), writable (weaker motors).
    pub fn actuator_gear_mut(&mut self) -> &mut [f64] {
        let n = 6 * self.nu();
        // SAFETY: `actuator_gear` has `6 * nu` entries and `&mut self` makes the slice the only access.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_mut().actuator_gear, n) }
    }
    /// Sets the gravity vector (world coordinates, m/s^2).
    pub fn set_gravity(&mut self, g: [f64; 3]) {
        // SAFETY: `&mut self` makes this the only access to the model.
        unsafe { self.ptr.as_mut().opt.gravity = g };
    }
    /// Heightfield `id`'s grid size (rows along y, columns along x) and its elevation samples in
    /// [0, 1] (`hfield_data`, row-major), writable.
    pub fn hfield_data_mut(&mut self, id: usize) -> (usize, usize, &mut [f32]) {
        let r = self.raw();
        assert!(id < r.nhfield as usize, "heightfield {id} out of range");
        // SAFETY: MuJoCo allocates nrow/ncol/adr with one entry per heightfield; `id` is in range.
        let (nrow, ncol, adr) = unsafe {
            (*r.hfield_nrow.add(id) as usize, *r.hfield_ncol.add(id) as usize, *r.hfield_adr.add(id) as usize)
        };
        // SAFETY: heightfield `id`'s samples are `nrow * ncol` floats from `adr` in `hfield_data`;
        // `&mut self` makes the slice the only access.
        let data = unsafe { std::slice::from_raw_parts_mut(self.ptr.as_mut().hfield_data.add(adr), nrow * ncol) };
        (nrow, ncol, data)
    }
    /// Sets the simulation time step in seconds.
    pub fn set_timestep(&mut self, dt: f64) {
        // SAFETY: `&mut self` makes this the only access to the model.
        unsafe { self.ptr.as_mut().opt.timestep = dt };
    }

    fn slice_f64(&self, p: *const f64, n: usize) -> &[f64] {
        if n == 0 {
            &[]
        } else {
            // SAFETY: callers pass a model array with at least `n` entries (n > 0 here), which lives as long
            // as `self`.
            unsafe { std::slice::from_raw_parts(p, n) }
        }
    }
    fn slice_i32(&self, p: *const i32, n: usize) -> &[i32] {
        if n == 0 {
            &[]
        } else {
            // SAFETY: callers pass a model array with at least `n` entries (n > 0 here), which lives as long
            // as `self`.
            unsafe { std::slice::from_raw_parts(p, n) }
        }
    }
}

impl Drop for Model {
    fn drop(&mut self) {
        // SAFETY: `ptr` came from MuJoCo and is freed exactly once, here; every state holds an `Arc` to its
        // model, so none outlives it.
        unsafe { sys::mj_deleteModel(self.ptr.as_ptr()) };
    }
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Model(nq={}, nv={}, nu={}, nbody={})", self.nq(), self.nv(), self.nu(), self.nbody())
    }
}

/// MuJoCo's library version (222 for 2.2.2).
pub fn version() -> i32 {
    // SAFETY: mj_version takes no arguments and touches no state.
    unsafe { sys::mj_version() }
}
