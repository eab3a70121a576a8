//! The static scene: every geom as the matching rerun primitive, under its body's entity.
use anyhow::Result;
use nalgebra::{Quaternion as NaQuat, UnitQuaternion, Vector3};
use rerun::components::FillMode;
use rerun::{Color, Quaternion, RecordingStream};

use crate::mujoco::{Model, ObjKind};

// MuJoCo's geom type codes (mjtGeom).
const PLANE: i32 = 0;
const SPHERE: i32 = 2;
const CAPSULE: i32 = 3;
const ELLIPSOID: i32 = 4;
const CYLINDER: i32 = 5;
const BOX: i32 = 6;
const MESH: i32 = 7;

/// Half extent drawn for an infinite plane (MuJoCo size 0).
const INFINITE_PLANE_HALF_EXTENT: f64 = 50.0;

/// Entity path of body `body`: `world/<name>` (`world/body_<id>` when unnamed); the world body
/// itself is `world`.
pub fn body_entity(model: &Model, body: usize) -> String {
    if body == 0 {
        return "world".to_string();
    }
    let name = model.name(ObjKind::Body, body).ok().flatten().unwrap_or_else(|| format!("body_{body}"));
    format!("world/{}", sanitize(&name))
}

fn geom_entity(model: &Model, geom: usize) -> String {
    let body = model.geom_body()[geom] as usize;
    let name = model.name(ObjKind::Geom, geom).ok().flatten().unwrap_or_else(|| format!("geom_{geom}"));
    format!("{}/{}", body_entity(model, body), sanitize(&name))
}

/// Entity path parts may not contain `/`; MuJoCo names may.
fn sanitize(name: &str) -> String {
    name.chars().map(|c| if c == '/' || c.is_whitespace() { '_' } else { c }).collect()
}

/// MuJoCo stores quaternions w, x, y, z; rerun takes x, y, z, w.
pub(crate) fn rerun_quat(wxyz: &[f64]) -> Quaternion {
    Quaternion::from_xyzw([wxyz[1] as f32, wxyz[2] as f32, wxyz[3] as f32, wxyz[0] as f32])
}

fn color(rgba: [f32; 4]) -> Color {
    let c = rgba.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
    Color::from_unmultiplied_rgba(c[0], c[1], c[2], c[3])
}

/// A geom's pose in its body frame.
struct LocalPose {
    pos: Vector3<f64>,
    rot: UnitQuaternion<f64>,
}

impl LocalPose {
    fn of(model: &Model, geom: usize) -> LocalPose {
        let p = &model.geom_pos()[3 * geom..3 * geom + 3];
        let q = &model.geom_quat()[4 * geom..4 * geom + 4];
        LocalPose {
            pos: Vector3::new(p[0], p[1], p[2]),
            rot: UnitQuaternion::from_quaternion(NaQuat::new(q[0], q[1], q[2], q[3])),
        }
    }
    fn apply(&self, v: Vector3<f64>) -> [f32; 3] {
        let w = self.pos + self.rot * v;
        [w.x as f32, w.y as f32, w.z as f32]
    }
    fn center(&self) -> [f32; 3] {
        [self.pos.x as f32, self.pos.y as f32, self.pos.z as f32]
    }
    fn quat(&self) -> Quaternion {
        let q = self.rot.quaternion();
        Quaternion::from_xyzw([q.i as f32, q.j as f32, q.k as f32, q.w as f32])
    }
}

/// Logs every geom once, statically. Returns the entity paths written, in geom order (geoms
/// that cannot be drawn, such as height fields, are skipped).
pub fn log_scene(rec: &RecordingStream, model: &Model) -> Result<Vec<String>> {
    let mut written = Vec::new();
    for geom in 0..model.ngeom() {
        let path = geom_entity(model, geom);
        let s = &model.geom_size()[3 * geom..3 * geom + 3];
        let pose = LocalPose::of(model, geom);
        let c = color(model.geom_color(geom));
        let (r, h) = (s[0] as f32, s[1] as f32);
        match model.geom_type()[geom] {
            SPHERE | ELLIPSOID => {
                let half =
                    if model.geom_type()[geom] == SPHERE { [r, r, r] } else { [s[0], s[1], s[2]].map(|v| v as f32) };
                rec.log_static(
                    path.as_str(),
                    &rerun::Ellipsoids3D::from_centers_and_half_sizes([pose.center()], [half])
                        .with_quaternions([pose.quat()])
                        .with_colors([c])
                        .with_fill_mode(FillMode::Solid),
                )?;
            }
            BOX => {
                rec.log_static(
                    path.as_str(),
                    &rerun::Boxes3D::from_centers_and_half_sizes(
                        [pose.center()],
                        [[s[0], s[1], s[2]].map(|v| v as f32)],
                    )
                    .with_quaternions([pose.quat()])
                    .with_colors([c])
                    .with_fill_mode(FillMode::Solid),
                )?;
            }
            // rerun's capsule runs from its origin along +z for `length`; MuJoCo's is centred.
            CAPSULE => {
                rec.log_static(
                    path.as_str(),
                    &rerun::Capsules3D::from_lengths_and_radii([2.0 * h], [r])
                        .with_translations([pose.apply(Vector3::new(0.0, 0.0, -s[1]))])
                        .with_quaternions([pose.quat()])
                        .with_colors([c]),
                )?;
            }
            CYLINDER => {
                rec.log_static(
                    path.as_str(),
                    &rerun::Cylinders3D::from_lengths_and_radii([2.0 * h], [r])
                        .with_centers([pose.center()])
                        .with_quaternions([pose.quat()])
                        .with_colors([c])
                        .with_fill_mode(FillMode::Solid),
                )?;
            }
            PLANE => {
                let half = |v: f64| if v > 0.0 { v } else { INFINITE_PLANE_HALF_EXTENT };
                let (hx, hy) = (half(s[0]), half(s[1]));
                let corners =
                    [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)].map(|(x, y)| pose.apply(Vector3::new(x, y, 0.0)));
                rec.log_static(
                    path.as_str(),
                    &rerun::Mesh3D::new(corners)
                        .with_triangle_indices([[0u32, 1, 2], [0, 2, 3]])
                        .with_albedo_factor(c.0),
                )?;
            }
            MESH => {
                let mesh = model.geom_dataid()[geom];
                if mesh < 0 {
                    continue;
                }
                let (verts, faces) = model.mesh(mesh as usize)?;
                let verts: Vec<[f32; 3]> =
                    verts.iter().map(|v| pose.apply(Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64))).collect();
                rec.log_static(
                    path.as_str(),
                    &rerun::Mesh3D::new(verts).with_triangle_indices(faces).with_albedo_factor(c.0),
                )?;
            }
            _ => continue, // height fields (1) and anything newer are not drawn
        }
        written.push(path);
    }
    Ok(written)
}
