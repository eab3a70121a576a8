//! Offscreen rendering of a simulation state with MuJoCo's own renderer (`mjv_` builds the
//! abstract scene, `mjr_` draws it with OpenGL), on a context that needs no display
//! ([`gl`]: OSMesa by default, EGL with `MUJOCO_GL=egl`). Frames are RGB, rows top-down.
//!
//! The sequence is MuJoCo's documented offscreen one (MuJoCo's `sample/record.cc`):
//! `mjv_makeScene`, `mjr_makeContext`, then per frame `mjv_updateScene`,
//! `mjr_setBuffer(mjFB_OFFSCREEN)`, `mjr_render` and `mjr_readPixels`.
pub mod gl;

use std::sync::Arc;

use anyhow::{bail, Context, Result};

use crate::mujoco::{sys, Data, Model, ObjKind};
pub use gl::Backend;

/// Where the camera looks from.
#[derive(Debug, Clone, PartialEq)]
pub enum Camera {
    /// Follows the robot's base (its first body) from the side and a little above, at a
    /// distance of four times the robot's radius, like Gymnasium's default MuJoCo camera.
    Follow,
    /// One of the model's own cameras, by name.
    Fixed(String),
    /// A free camera at `distance` (m) from the base's starting position, `azimuth` and
    /// `elevation` in degrees (MuJoCo's convention: elevation negative looks down).
    Free {
        /// Metres from the point looked at.
        distance: f64,
        /// Degrees around the vertical axis.
        azimuth: f64,
        /// Degrees above (positive) or below (negative) the horizon.
        elevation: f64,
    },
}

impl Camera {
    /// `follow`, `fixed:NAME` or `free:DISTANCE,AZIMUTH,ELEVATION`.
    pub fn parse(spec: &str) -> Result<Camera> {
        if spec == "follow" {
            return Ok(Camera::Follow);
        }
        if let Some(name) = spec.strip_prefix("fixed:") {
            if name.is_empty() {
                bail!("camera 'fixed:' needs the model camera's name (fixed:NAME)");
            }
            return Ok(Camera::Fixed(name.to_string()));
        }
        if let Some(values) = spec.strip_prefix("free:") {
            let v: Vec<f64> =
                values.split(',').map(|x| x.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| {
                    anyhow::anyhow!("camera '{spec}': free:DISTANCE,AZIMUTH,ELEVATION takes three numbers")
                })?;
            if v.len() != 3 || !v.iter().all(|x| x.is_finite()) || v[0] <= 0.0 {
                bail!("camera '{spec}': free:DISTANCE,AZIMUTH,ELEVATION takes three finite numbers, the distance > 0");
            }
            return Ok(Camera::Free { distance: v[0], azimuth: v[1], elevation: v[2] });
        }
        bail!("unknown camera '{spec}': follow (the default), fixed:NAME (a camera of the model) or free:DISTANCE,AZIMUTH,ELEVATION")
    }
}

/// What a renderer draws: size and camera.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderSettings {
    /// Frame width in pixels.
    pub width: usize,
    /// Frame height in pixels.
    pub height: usize,
    /// The camera.
    pub camera: Camera,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings { width: 640, height: 480, camera: Camera::Follow }
    }
}

/// One rendered frame: RGB bytes, rows top-down.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height * 3` bytes, row by row from the top.
    pub rgb: Vec<u8>,
}

impl Frame {
    /// The frame at half its width and height, each pixel the mean of a 2x2 block (an odd last
    /// row or column is dropped).
    pub fn half(&self) -> Frame {
        let (w, h) = (self.width / 2, self.height / 2);
        let mut rgb = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    let at = |dx: usize, dy: usize| self.rgb[((2 * y + dy) * self.width + 2 * x + dx) * 3 + c] as u16;
                    rgb.push(((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1) + 2) / 4) as u8);
                }
            }
        }
        Frame { width: w, height: h, rgb }
    }

    /// The pixel at column `x`, row `y` (from the top).
    pub fn pixel(&self, x: usize, y: usize) -> [u8; 3] {
        let i = (y * self.width + x) * 3;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }
}

/// What is drawn over a frame besides the scene.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Marks {
    /// Top-left text in MuJoCo's font: a column of names and a column of values, lines
    /// separated by `\n`.
    pub caption: Option<(String, String)>,
    /// A red arrow in the scene, from the first point to the second (world frame, metres).
    pub arrow: Option<([f64; 3], [f64; 3])>,
}

/// Renders states of one model. Holds an OpenGL context current on the thread that made it, so
/// it stays on that thread (not `Send`).
pub struct Renderer {
    model: Model,
    scene: Box<sys::mjvScene>,
    context: Box<sys::mjrContext>,
    option: Box<sys::mjvOption>,
    camera: Box<sys::mjvCamera>,
    settings: RenderSettings,
    // Dropped last: the MuJoCo context is freed while it is still current.
    gl: gl::GlContext,
}

/// The largest frame side MuJoCo 2.2's offscreen buffer is made with here.
const MAX_SIDE: usize = 4096;

impl Renderer {
    /// A renderer for `model`'s states on the backend `MUJOCO_GL` names.
    pub fn new(model: &Arc<Model>, settings: RenderSettings) -> Result<Renderer> {
        Renderer::with_backend(model, settings, Backend::from_env()?)
    }

    /// A renderer on `backend`.
    pub fn with_backend(model: &Arc<Model>, settings: RenderSettings, backend: Backend) -> Result<Renderer> {
        let (w, h) = (settings.width, settings.height);
        if !(16..=MAX_SIDE).contains(&w) || !(16..=MAX_SIDE).contains(&h) {
            bail!("render size {w}x{h}: each side must be 16 to {MAX_SIDE} pixels");
        }
        let gl = gl::GlContext::new(backend, w, h)?;
        let mut copy = model.try_clone()?;
        copy.set_offscreen_size(w, h);
        if backend == Backend::OsMesa {
            // On the CPU, MuJoCo's default 4x multisampling doubles a frame's time and a 4096
            // texel shadow map costs more than it shows at these sizes (measured: 640x480
            // Minitaur, 72 ms a frame against 140 ms with the defaults); EGL's GPU keeps them.
            copy.set_render_quality(1024, 0);
        }
        let fixed = match &settings.camera {
            Camera::Fixed(name) => Some(copy.id(ObjKind::Camera, name).map_err(|_| {
                let names: Vec<String> =
                    (0..copy.ncam()).filter_map(|i| copy.name(ObjKind::Camera, i).ok().flatten()).collect();
                anyhow::anyhow!(
                    "unknown camera 'fixed:{name}': the model's cameras are {}",
                    if names.is_empty() { "none (use follow or free:...)".to_string() } else { names.join(", ") }
                )
            })?),
            _ => None,
        };
        // SAFETY: zeroed MuJoCo structs are what their mj*_default functions then initialise.
        let (mut scene, mut context, mut option, mut camera) = unsafe {
            (
                Box::new(std::mem::zeroed::<sys::mjvScene>()),
                Box::new(std::mem::zeroed::<sys::mjrContext>()),
                Box::new(std::mem::zeroed::<sys::mjvOption>()),
                Box::new(std::mem::zeroed::<sys::mjvCamera>()),
            )
        };
        // SAFETY: each pointer is to a live, exclusively borrowed struct of the right type; the
        // scene is allocated for 2000 geoms and freed in `drop`.
        unsafe {
            sys::mjv_defaultScene(scene.as_mut());
            sys::mjv_defaultOption(option.as_mut());
            sys::mjv_defaultCamera(camera.as_mut());
            sys::mjr_defaultContext(context.as_mut());
            sys::mjv_makeScene(copy.as_ptr(), scene.as_mut(), 2000);
        }
        // SAFETY: the GL context is current on this thread; the model and context are live.
        if unsafe { sys::lb_make_render_context(copy.as_ptr(), context.as_mut()) } != 0 {
            let why = crate::mujoco::last_engine_error();
            // SAFETY: the scene was made above.
            unsafe { sys::mjv_freeScene(scene.as_mut()) };
            bail!("MuJoCo could not make its rendering context on {} ({why})", gl.backend().name());
        }
        let base = 1.min(copy.nbody().saturating_sub(1)) as i32;
        match (&settings.camera, fixed) {
            (_, Some(id)) => {
                camera.type_ = sys::mjtCamera__mjCAMERA_FIXED as i32;
                camera.fixedcamid = id as i32;
            }
            (Camera::Free { distance, azimuth, elevation }, _) => {
                camera.type_ = sys::mjtCamera__mjCAMERA_FREE as i32;
                camera.distance = *distance;
                camera.azimuth = *azimuth;
                camera.elevation = *elevation;
                // The base's initial position: a free camera stays where it was put.
                camera.lookat = [0.0, 0.0, copy.body_pos(base as usize)[2]];
            }
            _ => {
                // A free camera moved onto the base at every frame: MuJoCo's tracking camera
                // follows with a lag, which puts a fast robot at the frame's edge.
                camera.type_ = sys::mjtCamera__mjCAMERA_FREE as i32;
                camera.trackbodyid = base;
                // Set from the robot's size at the first frame (`fit_follow`).
                camera.distance = 0.0;
                camera.azimuth = 90.0;
                camera.elevation = -20.0;
            }
        }
        Ok(Renderer { model: copy, scene, context, option, camera, settings, gl })
    }

    /// The follow camera's distance: 4 times the radius of the sphere around the base that
    /// holds every geom of the robot (not the world's floor) in `data`'s state.
    fn fit_follow(&mut self, data: &Data) {
        let base = self.camera.trackbodyid.max(0) as usize;
        let (xpos, geoms, bodies, rbound) =
            (data.xpos(), data.geom_xpos(), self.model.geom_body(), self.model.geom_rbound());
        let centre = &xpos[3 * base..3 * base + 3];
        let radius = (0..self.model.ngeom())
            .filter(|&g| bodies[g] != 0)
            .map(|g| {
                let d: f64 = (0..3).map(|k| (geoms[3 * g + k] - centre[k]).powi(2)).sum::<f64>().sqrt();
                d + rbound[g]
            })
            .fold(0.0f64, f64::max);
        self.camera.distance = (4.0 * radius).max(0.5);
    }

    /// The settings it draws with.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// The OpenGL backend it draws on.
    pub fn backend(&self) -> Backend {
        self.gl.backend()
    }

    /// The model it draws (its own copy, with the offscreen size set).
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Draws `data` (a state of the model this renderer was made for).
    pub fn render(&mut self, data: &Data) -> Result<Frame> {
        self.render_marked(data, &Marks::default())
    }

    /// Draws `data` with `marks` over it.
    pub fn render_marked(&mut self, data: &Data, marks: &Marks) -> Result<Frame> {
        let m = data.model();
        if m.nq() != self.model.nq() || m.nbody() != self.model.nbody() || m.ngeom() != self.model.ngeom() {
            bail!("the state belongs to another model than this renderer's");
        }
        if self.settings.camera == Camera::Follow {
            if self.camera.distance == 0.0 {
                self.fit_follow(data);
            }
            let base = self.camera.trackbodyid.max(0) as usize;
            self.camera.lookat.copy_from_slice(&data.xpos()[3 * base..3 * base + 3]);
        }
        let (w, h) = (self.settings.width, self.settings.height);
        let mut flipped = vec![0u8; w * h * 3];
        let text = |s: &str| std::ffi::CString::new(s.replace('\0', " ")).expect("NULs replaced");
        let caption = marks.caption.as_ref().map(|(a, b)| (text(a), text(b)));
        let arrow = marks.arrow.map(|(a, b)| [a[0], a[1], a[2], b[0], b[1], b[2]]);
        // SAFETY: the GL context is current on this thread (a Renderer never leaves it); every
        // pointer is live; `flipped` holds w*h*3 bytes for the read-back; mjv_updateScene only
        // reads the state.
        let rc = unsafe {
            sys::lb_render_frame(
                self.model.as_ptr(),
                data.as_ptr_for_reading(),
                self.option.as_ref(),
                self.camera.as_mut(),
                self.scene.as_mut(),
                self.context.as_mut(),
                w as i32,
                h as i32,
                flipped.as_mut_ptr(),
                caption.as_ref().map_or(std::ptr::null(), |c| c.0.as_ptr()),
                caption.as_ref().map_or(std::ptr::null(), |c| c.1.as_ptr()),
                arrow.as_ref().map_or(std::ptr::null(), |a| a.as_ptr()),
            )
        };
        if rc != 0 {
            bail!("rendering failed: {}", crate::mujoco::last_engine_error());
        }
        // OpenGL's rows run bottom-up.
        let row = w * 3;
        let mut rgb = Vec::with_capacity(w * h * 3);
        for y in (0..h).rev() {
            rgb.extend_from_slice(&flipped[y * row..(y + 1) * row]);
        }
        Ok(Frame { width: w, height: h, rgb })
    }
}

impl Drop for Renderer {
    fn drop(&mut self) {
        // SAFETY: made in `with_backend`, freed once, with the GL context still current.
        unsafe {
            sys::mjr_freeContext(self.context.as_mut());
            sys::mjv_freeScene(self.scene.as_mut());
        }
    }
}

/// Checks that a renderer can be made here (a GL library and context), for a clear error before
/// any long work starts.
pub fn check_available(model: &Arc<Model>) -> Result<()> {
    Renderer::new(model, RenderSettings { width: 16, height: 16, camera: Camera::Follow })
        .map(drop)
        .context("rendering is not available on this machine")
}

pub mod clip;
pub mod film;
pub mod video;

pub use clip::tile;
pub use film::{frame_stride, Film};
