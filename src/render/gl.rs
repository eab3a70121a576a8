//! An OpenGL context with no display, for MuJoCo's renderer: Mesa's OSMesa (software, any
//! machine; the default) or EGL (a GPU's driver, or Mesa's surfaceless platform), picked by
//! `MUJOCO_GL` as Gymnasium and dm_control do. The library is opened with `dlopen` when the first
//! renderer is made, so nothing else in locobench needs it installed.
//!
//! MuJoCo 2.2 loads its GL functions itself, through `OSMesaGetProcAddress` or
//! `eglGetProcAddress` (it names `libOSMesa.so` and `libEGL.so`); the library is opened with
//! `RTLD_GLOBAL` so that it finds them in this process. MuJoCo then draws into its own offscreen
//! framebuffer, so the context needs no surface of its own beyond OSMesa's buffer.
use std::ffi::{c_void, CString};

use anyhow::{bail, Result};

/// Which OpenGL provider renders.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// Mesa's off-screen software renderer (Debian's `libosmesa6`).
    OsMesa,
    /// EGL without a display: a GPU driver's, or Mesa's (`libegl1`, `libegl-mesa0`).
    Egl,
}

impl Backend {
    /// From `MUJOCO_GL` (`osmesa`, the default, or `egl`); anything else is an error naming it.
    pub fn from_env() -> Result<Backend> {
        match std::env::var("MUJOCO_GL") {
            Err(_) => Ok(Backend::OsMesa),
            Ok(v) => Backend::parse(&v),
        }
    }

    /// `osmesa` or `egl`.
    pub fn parse(name: &str) -> Result<Backend> {
        match name.to_ascii_lowercase().as_str() {
            "" | "osmesa" => Ok(Backend::OsMesa),
            "egl" => Ok(Backend::Egl),
            other => {
                bail!("MUJOCO_GL={other:?} is not a backend locobench renders with: use osmesa (the default) or egl")
            }
        }
    }

    fn libraries(self) -> &'static [&'static str] {
        match self {
            Backend::OsMesa => &["libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so"],
            Backend::Egl => &["libEGL.so.1", "libEGL.so"],
        }
    }

    fn package(self) -> &'static str {
        match self {
            Backend::OsMesa => "libosmesa6",
            Backend::Egl => "libegl1 and libegl-mesa0 (or a GPU driver's EGL)",
        }
    }

    /// The name `MUJOCO_GL` takes.
    pub fn name(self) -> &'static str {
        match self {
            Backend::OsMesa => "osmesa",
            Backend::Egl => "egl",
        }
    }
}

struct Library(*mut c_void);

impl Library {
    fn open(backend: Backend) -> Result<Library> {
        let mut tried = Vec::new();
        for name in backend.libraries() {
            let c = CString::new(*name).expect("no NUL");
            // SAFETY: dlopen with a NUL-terminated name; a null return is handled below.
            let handle = unsafe { libc::dlopen(c.as_ptr(), libc::RTLD_NOW | libc::RTLD_GLOBAL) };
            if !handle.is_null() {
                return Ok(Library(handle));
            }
            tried.push(*name);
        }
        bail!(
            "rendering with MUJOCO_GL={} needs {} ({} not found); install it (`apt-get install {}`, which \
             scripts/setup.sh does), or set MUJOCO_GL={} to use the other backend",
            backend.name(),
            backend.package(),
            tried.join(", "),
            match backend {
                Backend::OsMesa => "libosmesa6",
                Backend::Egl => "libegl1 libegl-mesa0",
            },
            match backend {
                Backend::OsMesa => "egl",
                Backend::Egl => "osmesa",
            }
        )
    }

    /// The address of `symbol`, or an error naming it.
    fn symbol(&self, symbol: &str) -> Result<*mut c_void> {
        let c = CString::new(symbol).expect("no NUL");
        // SAFETY: `self.0` is a live handle from dlopen; the name is NUL-terminated.
        let address = unsafe { libc::dlsym(self.0, c.as_ptr()) };
        if address.is_null() {
            bail!("the OpenGL library has no {symbol}");
        }
        Ok(address)
    }
}

// The few entry points used, by their C signatures (OSMesa's osmesa.h, Khronos' egl.h).
type OsMesaCreateContextExt = unsafe extern "C" fn(u32, i32, i32, i32, *mut c_void) -> *mut c_void;
type OsMesaMakeCurrent = unsafe extern "C" fn(*mut c_void, *mut c_void, u32, i32, i32) -> u8;
type OsMesaDestroyContext = unsafe extern "C" fn(*mut c_void);
type EglGetProcAddress = unsafe extern "C" fn(*const i8) -> *mut c_void;
type EglGetPlatformDisplay = unsafe extern "C" fn(u32, *mut c_void, *const isize) -> *mut c_void;
type EglGetDisplay = unsafe extern "C" fn(*mut c_void) -> *mut c_void;
type EglInitialize = unsafe extern "C" fn(*mut c_void, *mut i32, *mut i32) -> u32;
type EglChooseConfig = unsafe extern "C" fn(*mut c_void, *const i32, *mut *mut c_void, i32, *mut i32) -> u32;
type EglBindApi = unsafe extern "C" fn(u32) -> u32;
type EglCreateContext = unsafe extern "C" fn(*mut c_void, *mut c_void, *mut c_void, *const i32) -> *mut c_void;
type EglMakeCurrent = unsafe extern "C" fn(*mut c_void, *mut c_void, *mut c_void, *mut c_void) -> u32;
type EglDestroyContext = unsafe extern "C" fn(*mut c_void, *mut c_void) -> u32;
type EglGetError = unsafe extern "C" fn() -> i32;

const GL_RGBA: u32 = 0x1908;
const GL_UNSIGNED_BYTE: u32 = 0x1401;
const EGL_PLATFORM_SURFACELESS_MESA: u32 = 0x31DD;
const EGL_OPENGL_API: u32 = 0x30A2;
const EGL_NONE: i32 = 0x3038;
const EGL_RED_SIZE: i32 = 0x3024;
const EGL_GREEN_SIZE: i32 = 0x3023;
const EGL_BLUE_SIZE: i32 = 0x3022;
const EGL_ALPHA_SIZE: i32 = 0x3021;
const EGL_DEPTH_SIZE: i32 = 0x3025;
const EGL_STENCIL_SIZE: i32 = 0x3026;
const EGL_RENDERABLE_TYPE: i32 = 0x3040;
const EGL_SURFACE_TYPE: i32 = 0x3033;
const EGL_PBUFFER_BIT: i32 = 0x0001;
const EGL_OPENGL_BIT: i32 = 0x0008;

enum Handles {
    OsMesa { context: *mut c_void, buffer: Vec<u8>, destroy: OsMesaDestroyContext },
    Egl { display: *mut c_void, context: *mut c_void, destroy: EglDestroyContext },
}

/// A current OpenGL context on the thread that made it. Not `Send`: a GL context is current on
/// one thread.
pub struct GlContext {
    backend: Backend,
    handles: Handles,
    _library: Library,
}

impl GlContext {
    /// Makes a context current on this thread, with a `width` x `height` buffer (OSMesa's own;
    /// MuJoCo draws into its offscreen framebuffer of the model's size).
    pub fn new(backend: Backend, width: usize, height: usize) -> Result<GlContext> {
        let library = Library::open(backend)?;
        let handles = match backend {
            Backend::OsMesa => osmesa(&library, width, height)?,
            Backend::Egl => egl(&library)?,
        };
        Ok(GlContext { backend, handles, _library: library })
    }

    /// The backend in use.
    pub fn backend(&self) -> Backend {
        self.backend
    }
}

fn osmesa(library: &Library, width: usize, height: usize) -> Result<Handles> {
    // SAFETY: the symbols have these C signatures (osmesa.h).
    let (create, make_current, destroy) = unsafe {
        (
            std::mem::transmute::<*mut c_void, OsMesaCreateContextExt>(library.symbol("OSMesaCreateContextExt")?),
            std::mem::transmute::<*mut c_void, OsMesaMakeCurrent>(library.symbol("OSMesaMakeCurrent")?),
            std::mem::transmute::<*mut c_void, OsMesaDestroyContext>(library.symbol("OSMesaDestroyContext")?),
        )
    };
    // SAFETY: RGBA with 24 depth, 8 stencil and no accumulation bits, sharing with no context.
    let context = unsafe { create(GL_RGBA, 24, 8, 0, std::ptr::null_mut()) };
    if context.is_null() {
        bail!("OSMesaCreateContextExt failed: Mesa could not make a software OpenGL context");
    }
    let mut buffer = vec![0u8; width.max(1) * height.max(1) * 4];
    // SAFETY: `buffer` holds width x height RGBA bytes and lives as long as the context (it moves
    // with `Handles`, but a Vec's heap storage does not move).
    let ok =
        unsafe { make_current(context, buffer.as_mut_ptr().cast(), GL_UNSIGNED_BYTE, width as i32, height as i32) };
    if ok == 0 {
        // SAFETY: the context was created above and is not current.
        unsafe { destroy(context) };
        bail!("OSMesaMakeCurrent failed for a {width}x{height} buffer");
    }
    Ok(Handles::OsMesa { context, buffer, destroy })
}

fn egl(library: &Library) -> Result<Handles> {
    // SAFETY: the symbols have these C signatures (egl.h).
    let (get_proc, get_display, initialize, choose, bind, create, make_current, destroy, get_error) = unsafe {
        (
            std::mem::transmute::<*mut c_void, EglGetProcAddress>(library.symbol("eglGetProcAddress")?),
            std::mem::transmute::<*mut c_void, EglGetDisplay>(library.symbol("eglGetDisplay")?),
            std::mem::transmute::<*mut c_void, EglInitialize>(library.symbol("eglInitialize")?),
            std::mem::transmute::<*mut c_void, EglChooseConfig>(library.symbol("eglChooseConfig")?),
            std::mem::transmute::<*mut c_void, EglBindApi>(library.symbol("eglBindAPI")?),
            std::mem::transmute::<*mut c_void, EglCreateContext>(library.symbol("eglCreateContext")?),
            std::mem::transmute::<*mut c_void, EglMakeCurrent>(library.symbol("eglMakeCurrent")?),
            std::mem::transmute::<*mut c_void, EglDestroyContext>(library.symbol("eglDestroyContext")?),
            std::mem::transmute::<*mut c_void, EglGetError>(library.symbol("eglGetError")?),
        )
    };
    let error = |what: &str| {
        // SAFETY: eglGetError takes nothing and returns the thread's last error code.
        anyhow::anyhow!("{what} failed (EGL error {:#x}); with no GPU, MUJOCO_GL=osmesa renders on the CPU", unsafe {
            get_error()
        })
    };
    // Mesa's surfaceless platform needs no display server; a GPU driver's default display works too.
    let name = CString::new("eglGetPlatformDisplayEXT").expect("no NUL");
    // SAFETY: a NUL-terminated name; a null result means the extension is absent.
    let platform = unsafe { get_proc(name.as_ptr().cast()) };
    let mut display = std::ptr::null_mut();
    if !platform.is_null() {
        // SAFETY: eglGetPlatformDisplayEXT's signature (EGL_EXT_platform_base).
        let get_platform = unsafe { std::mem::transmute::<*mut c_void, EglGetPlatformDisplay>(platform) };
        // SAFETY: the surfaceless platform takes EGL_DEFAULT_DISPLAY (null) and no attributes.
        display = unsafe { get_platform(EGL_PLATFORM_SURFACELESS_MESA, std::ptr::null_mut(), std::ptr::null()) };
    }
    if display.is_null() {
        // SAFETY: EGL_DEFAULT_DISPLAY is null.
        display = unsafe { get_display(std::ptr::null_mut()) };
    }
    if display.is_null() {
        return Err(error("eglGetDisplay"));
    }
    let (mut major, mut minor) = (0, 0);
    // SAFETY: a display from above and two writable ints.
    if unsafe { initialize(display, &mut major, &mut minor) } == 0 {
        return Err(error("eglInitialize"));
    }
    let attributes = [
        EGL_RED_SIZE,
        8,
        EGL_GREEN_SIZE,
        8,
        EGL_BLUE_SIZE,
        8,
        EGL_ALPHA_SIZE,
        8,
        EGL_DEPTH_SIZE,
        24,
        EGL_STENCIL_SIZE,
        8,
        EGL_RENDERABLE_TYPE,
        EGL_OPENGL_BIT,
        // The default asks for window surfaces, which a display-less EGL has none of.
        EGL_SURFACE_TYPE,
        EGL_PBUFFER_BIT,
        EGL_NONE,
    ];
    let mut config = std::ptr::null_mut();
    let mut found = 0;
    // SAFETY: a NONE-terminated attribute list, room for one config and its count.
    if unsafe { choose(display, attributes.as_ptr(), &mut config, 1, &mut found) } == 0 || found < 1 {
        return Err(error("eglChooseConfig (RGBA8, depth 24, stencil 8, desktop OpenGL)"));
    }
    // SAFETY: binding the desktop OpenGL API for this thread.
    if unsafe { bind(EGL_OPENGL_API) } == 0 {
        return Err(error("eglBindAPI(EGL_OPENGL_API)"));
    }
    let no_attributes = [EGL_NONE];
    // SAFETY: a display and config from above, no shared context, an empty attribute list.
    let context = unsafe { create(display, config, std::ptr::null_mut(), no_attributes.as_ptr()) };
    if context.is_null() {
        return Err(error("eglCreateContext"));
    }
    // SAFETY: surfaceless: no draw or read surface (EGL_KHR_surfaceless_context); MuJoCo renders
    // into its own framebuffer object.
    if unsafe { make_current(display, std::ptr::null_mut(), std::ptr::null_mut(), context) } == 0 {
        // SAFETY: the context was created above and is not current.
        unsafe { destroy(display, context) };
        return Err(error("eglMakeCurrent (surfaceless)"));
    }
    Ok(Handles::Egl { display, context, destroy })
}

impl Drop for GlContext {
    fn drop(&mut self) {
        match &mut self.handles {
            // SAFETY: the context was made by this value and is destroyed once.
            Handles::OsMesa { context, destroy, buffer } => unsafe {
                destroy(*context);
                buffer.clear();
            },
            // SAFETY: as above, with its display.
            Handles::Egl { display, context, destroy } => unsafe {
                destroy(*display, *context);
            },
        }
    }
}
