//! Cameras and camera paths: a perspective camera looking from an eye at a target, and a path of
//! keyframes it moves along, one position per frame. Plain f32 math on the render thread.

use serde::{Deserialize, Serialize};

/// A perspective camera (y up, right-handed), for wgpu's clip space (depth 0..1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Where the camera is.
    pub eye: [f32; 3],
    /// The point it looks at.
    pub target: [f32; 3],
}

impl Camera {
    /// The column-major view-projection matrix for a vertical field of view of `fov_y_deg` and
    /// an `aspect` (width / height), with near and far planes scaled to the distance to the
    /// target so that depth precision follows the camera.
    pub fn view_proj(&self, fov_y_deg: f32, aspect: f32) -> [[f32; 4]; 4] {
        let [forward, right, up] = self.basis();
        let eye = self.eye;
        let view = [
            [right[0], up[0], -forward[0], 0.0],
            [right[1], up[1], -forward[1], 0.0],
            [right[2], up[2], -forward[2], 0.0],
            [-dot(right, eye), -dot(up, eye), dot(forward, eye), 1.0],
        ];
        let distance = length(sub(self.target, self.eye)).max(1e-6);
        let (near, far) = (distance * 1e-3, distance * 1e3);
        let f = focal(fov_y_deg);
        let proj = [
            [f / aspect, 0.0, 0.0, 0.0],
            [0.0, f, 0.0, 0.0],
            [0.0, 0.0, far / (near - far), -1.0],
            [0.0, 0.0, near * far / (near - far), 0.0],
        ];
        mul(&proj, &view)
    }

    /// The camera's forward, right and up unit vectors.
    fn basis(&self) -> [[f32; 3]; 3] {
        let forward = normalize(sub(self.target, self.eye));
        // Looking straight down or up: any horizontal "up" will do.
        let up_hint = if forward[1].abs() > 0.999 { [0.0, 0.0, -1.0] } else { [0.0, 1.0, 0.0] };
        let right = normalize(cross(forward, up_hint));
        [forward, right, cross(right, forward)]
    }

    /// The UV where the centre of pixel position (`x`, `y`) of a `frame` (width, height) sees the
    /// plane y = 0 of `Shape::Plane { size }` (a square centred on the origin, UV (0, 0) at
    /// (-size/2, -size/2)), as [`Camera::view_proj`] projects it; `None` where the ray misses the
    /// plane. The CPU side of a picture of the plane: references and ground truths need each
    /// pixel's UV (and, from its neighbours', its derivatives).
    pub fn plane_uv(&self, fov_y_deg: f32, frame: [f32; 2], size: f32, x: f32, y: f32) -> Option<[f32; 2]> {
        let [forward, right, up] = self.basis();
        let f = focal(fov_y_deg);
        let (nx, ny) = (2.0 * x / frame[0] - 1.0, 1.0 - 2.0 * y / frame[1]);
        let (sx, sy) = (nx * frame[0] / frame[1] / f, ny / f);
        let d: [f32; 3] = std::array::from_fn(|i| forward[i] + right[i] * sx + up[i] * sy);
        if d[1] >= 0.0 || self.eye[1] <= 0.0 {
            return None;
        }
        let t = -self.eye[1] / d[1];
        Some([(self.eye[0] + t * d[0]) / size + 0.5, (self.eye[2] + t * d[2]) / size + 0.5])
    }
}

/// The projection's focal length for a vertical field of view of `fov_y_deg`.
fn focal(fov_y_deg: f32) -> f32 {
    1.0 / (fov_y_deg.to_radians() / 2.0).tan()
}

/// One keyframe of a camera path: where the camera is at `frame`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Keyframe<T> {
    /// The frame.
    pub frame: u32,
    /// Where the camera is then (between keyframes it is interpolated).
    #[serde(flatten)]
    pub at: T,
}

/// Where a path is at `frame`: keyframes sorted by frame, eased (smoothstep) between
/// neighbours, held before the first and after the last.
pub fn at_frame<T: Copy>(keys: &[Keyframe<T>], frame: u32, lerp: impl Fn(&T, &T, f32) -> T) -> Option<T> {
    let first = keys.first()?;
    if frame <= first.frame {
        return Some(first.at);
    }
    let next = keys.iter().position(|k| k.frame > frame);
    Some(match next {
        None => keys[keys.len() - 1].at,
        Some(i) => {
            let (a, b) = (&keys[i - 1], &keys[i]);
            let t = (frame - a.frame) as f32 / (b.frame - a.frame) as f32;
            lerp(&a.at, &b.at, t * t * (3.0 - 2.0 * t))
        }
    })
}

pub(crate) fn lerp3(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    std::array::from_fn(|i| a[i] + (b[i] - a[i]) * t)
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn length(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

fn normalize(a: [f32; 3]) -> [f32; 3] {
    let l = length(a).max(1e-20);
    [a[0] / l, a[1] / l, a[2] / l]
}

/// `a * b` for column-major 4x4 matrices.
fn mul(a: &[[f32; 4]; 4], b: &[[f32; 4]; 4]) -> [[f32; 4]; 4] {
    std::array::from_fn(|col| std::array::from_fn(|row| (0..4).map(|k| a[k][row] * b[col][k]).sum()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn project(m: &[[f32; 4]; 4], p: [f32; 3]) -> [f32; 3] {
        let v: [f32; 4] = std::array::from_fn(|row| (0..3).map(|k| m[k][row] * p[k]).sum::<f32>() + m[3][row]);
        [v[0] / v[3], v[1] / v[3], v[2] / v[3]]
    }

    #[test]
    fn the_target_lands_in_the_middle_in_front() {
        let cam = Camera { eye: [0.3, 2.0, 1.5], target: [0.1, 0.0, -0.2] };
        let c = project(&cam.view_proj(60.0, 1.5), cam.target);
        assert!(c[0].abs() < 1e-5 && c[1].abs() < 1e-5 && (0.0..1.0).contains(&c[2]), "{c:?}");
        // Straight down works too, and a point to the camera's right lands right.
        let down = Camera { eye: [0.0, 3.0, 0.0], target: [0.0; 3] };
        let m = down.view_proj(90.0, 1.0);
        assert!(project(&m, [0.0; 3])[0].abs() < 1e-6);
        assert!(project(&m, [1.0, 0.0, 0.0])[0] > 0.2);
    }

    #[test]
    fn paths_ease_between_keyframes_and_hold_at_the_ends() {
        let keys = [Keyframe { frame: 2, at: 0.0f32 }, Keyframe { frame: 6, at: 1.0 }];
        let at = |f| at_frame(&keys, f, |a, b, t| a + (b - a) * t).unwrap();
        assert_eq!((at(0), at(2), at(4), at(6), at(60)), (0.0, 0.0, 0.5, 1.0, 1.0));
        assert!(at(3) < 0.25, "eased in");
        assert_eq!(at_frame::<f32>(&[], 3, |a, _, _| *a), None);
    }
}
