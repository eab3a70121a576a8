// MuJoCo's error handler must not return: the default one waits for Enter and exits. This shim
// installs a handler that jumps back to the guarded entry point below, so a fatal MuJoCo error
// becomes a return code and a message instead of ending the process. Only C frames (ours and
// MuJoCo's) lie between setjmp and longjmp; no Rust frame is ever skipped.
#include <mujoco/mujoco.h>
#include <setjmp.h>
#include <stdlib.h>
#include <string.h>

static _Thread_local jmp_buf* active_jump = NULL;
static _Thread_local char last_error[1024];

static void on_mujoco_error(const char* msg) {
  strncpy(last_error, msg ? msg : "unknown MuJoCo error", sizeof last_error - 1);
  last_error[sizeof last_error - 1] = '\0';
  if (active_jump) {
    longjmp(*active_jump, 1);
  }
  // No guarded call on this thread: nothing to jump to. Returning lets MuJoCo continue, which
  // is what it does for recoverable conditions; the message stays readable via lb_last_error.
}

void lb_install_handlers(void (*warning)(const char*)) {
  mju_user_error = on_mujoco_error;
  mju_user_warning = warning;
}

const char* lb_last_error(void) { return last_error; }

#define GUARDED(statement)           \
  do {                               \
    jmp_buf here;                    \
    jmp_buf* outer = active_jump;    \
    last_error[0] = '\0';            \
    if (setjmp(here) != 0) {         \
      active_jump = outer;           \
      return -1;                     \
    }                                \
    active_jump = &here;             \
    statement;                       \
    active_jump = outer;             \
    return 0;                        \
  } while (0)

int lb_step(const mjModel* m, mjData* d) { GUARDED(mj_step(m, d)); }
int lb_forward(const mjModel* m, mjData* d) { GUARDED(mj_forward(m, d)); }
int lb_rne_post_constraint(const mjModel* m, mjData* d) { GUARDED(mj_rnePostConstraint(m, d)); }
int lb_reset_data(const mjModel* m, mjData* d) { GUARDED(mj_resetData(m, d)); }

int lb_make_data(const mjModel* m, mjData** out) { GUARDED(*out = mj_makeData(m)); }
int lb_copy_model(const mjModel* m, mjModel** out) { GUARDED(*out = mj_copyModel(NULL, m)); }

int lb_jac_site(const mjModel* m, mjData* d, mjtNum* jacp, mjtNum* jacr, int site) {
  GUARDED(mj_jacSite(m, d, jacp, jacr, site));
}
int lb_jac_body(const mjModel* m, mjData* d, mjtNum* jacp, mjtNum* jacr, int body) {
  GUARDED(mj_jacBody(m, d, jacp, jacr, body));
}

static int load_xml(const char* path, const mjVFS* vfs, char* err, int err_len, mjModel** out) {
  GUARDED(*out = mj_loadXML(path, vfs, err, err_len));
}

int lb_load_xml_file(const char* path, char* err, int err_len, mjModel** out) {
  return load_xml(path, NULL, err, err_len, out);
}

// 2.2.2 has no load-from-string call; a one-file virtual file system stands in for it. The VFS
// struct is about 2 MB, so it lives on the heap.
int lb_load_xml_string(const char* name, const char* xml, int len, char* err, int err_len,
                       mjModel** out) {
  mjVFS* vfs = (mjVFS*)malloc(sizeof(mjVFS));
  if (!vfs) {
    strncpy(err, "out of memory allocating the MuJoCo VFS", err_len - 1);
    return 1;
  }
  mj_defaultVFS(vfs);
  if (mj_makeEmptyFileVFS(vfs, name, len) != 0) {
    strncpy(err, "could not create the in-memory model file", err_len - 1);
    free(vfs);
    return 1;
  }
  int slot = mj_findFileVFS(vfs, name);
  memcpy(vfs->filedata[slot], xml, (size_t)len);
  int rc = load_xml(name, vfs, err, err_len, out);
  mj_deleteVFS(vfs);
  free(vfs);
  return rc;
}

// Rendering (src/render/): the caller has made an OpenGL context current on this thread.
// mjr_makeContext reports a GL it cannot load through mju_error, which comes back here as -1.
int lb_make_render_context(const mjModel* m, mjrContext* con) {
  GUARDED(mjr_makeContext(m, con, mjFONTSCALE_100));
}

// One frame: the scene from the state, drawn into the offscreen buffer and read back (RGB, rows
// bottom-up as OpenGL stores them). Optional marks: a red arrow in the scene from arrow[0..3] to
// arrow[3..6] (a push), and a caption in MuJoCo's own font at the top left (labels in `caption`,
// their values in `caption2`, lines separated by '\n', as mjr_overlay draws them).
static void render_frame(const mjModel* m, mjData* d, const mjvOption* opt, mjvCamera* cam,
                         mjvScene* scn, mjrContext* con, int width, int height,
                         unsigned char* rgb, const char* caption, const char* caption2,
                         const double* arrow) {
  mjrRect viewport = {0, 0, width, height};
  mjv_updateScene(m, d, opt, NULL, cam, mjCAT_ALL, scn);
  if (arrow && scn->ngeom < scn->maxgeom) {
    const float red[4] = {0.9f, 0.1f, 0.1f, 1.0f};
    mjvGeom* g = scn->geoms + scn->ngeom;
    mjv_initGeom(g, mjGEOM_ARROW, NULL, NULL, NULL, red);
    mjv_makeConnector(g, mjGEOM_ARROW, 0.04, arrow[0], arrow[1], arrow[2], arrow[3], arrow[4], arrow[5]);
    g->category = mjCAT_DECOR;
    scn->ngeom++;
  }
  mjr_setBuffer(mjFB_OFFSCREEN, con);
  mjr_render(viewport, scn, con);
  if (caption && caption[0]) {
    mjr_overlay(mjFONT_NORMAL, mjGRID_TOPLEFT, viewport, caption, caption2, con);
  }
  mjr_readPixels(rgb, NULL, viewport, con);
}

int lb_render_frame(const mjModel* m, mjData* d, const mjvOption* opt, mjvCamera* cam, mjvScene* scn,
                    mjrContext* con, int width, int height, unsigned char* rgb, const char* caption,
                    const char* caption2, const double* arrow) {
  GUARDED(render_frame(m, d, opt, cam, scn, con, width, height, rgb, caption, caption2, arrow));
}
