//! The camera `analysis_speed` and `frame_cost` look through: 2 m above a ground plane that one 65536²
//! virtual texture covers (128 m, 2 mm per texel, repeating), pitched 40° down, 75° vertical field
//! of view, and the feedback pass of a 1280x720 frame at 1/8 (160x90 words) made on the CPU.

use vortex_vt::address::uv_at;
use vortex_vt::feedback::{NO_REQUEST, encode, lod_for};
use vortex_vt::page::{PageId, TextureGrid};

pub const FRAME: (u32, u32) = (1280, 720);
pub const FEEDBACK: (u32, u32) = (160, 90);
pub const SIDE_TEXELS: f32 = 65536.0;
pub const TEXTURE_SIDE_M: f32 = 128.0;

pub const VERTICAL_FOV: f32 = 75.0;
pub const PITCH: f32 = 40.0;
pub const HEIGHT_M: f32 = 2.0;
/// Walking speed, metres per frame (1.4 m/s at 60 frames per second).
pub const STEP_M: f32 = 1.4 / 60.0;

/// Where the camera stands (metres on the ground plane, from the texture's origin) and where it looks.
#[derive(Clone, Copy)]
pub struct Camera {
    pub x: f32,
    pub z: f32,
    pub yaw: f32,
}

impl Camera {
    /// The heading of frame `f`, in degrees: 30° + 0.1° per frame + a ±20° sway (period ~25 s).
    pub fn yaw_at(f: u64) -> f32 {
        let f = f as f32;
        30.0 + 0.1 * f + 20.0 * (f / 240.0).sin()
    }

    /// The camera of frame 0, at the texture's centre.
    pub fn start() -> Camera {
        Camera { x: TEXTURE_SIDE_M / 2.0, z: TEXTURE_SIDE_M / 2.0, yaw: Camera::yaw_at(0) }
    }

    /// From frame `f - 1` to frame `f`: one step forward, then the new heading.
    pub fn step(&mut self, f: u64) {
        let (s, c) = self.yaw.to_radians().sin_cos();
        (self.x, self.z) = (self.x - s * STEP_M, self.z + c * STEP_M);
        self.yaw = Camera::yaw_at(f);
    }

    /// UV (not yet wrapped) on the ground plane seen through feedback pixel position (px, py), or
    /// None above the horizon.
    pub fn uv(&self, px: f32, py: f32) -> Option<(f32, f32)> {
        let (w, h) = (FEEDBACK.0 as f32, FEEDBACK.1 as f32);
        let tan = (VERTICAL_FOV / 2.0).to_radians().tan();
        let x = (2.0 * px / w - 1.0) * tan * w / h;
        let y = (1.0 - 2.0 * py / h) * tan;
        // Ray (x, y, 1) in camera space, pitched down: its forward and downward components.
        let (s, c) = PITCH.to_radians().sin_cos();
        let forward = c + y * s;
        let down = s - y * c;
        if down <= 1e-4 {
            return None;
        }
        let t = HEIGHT_M / down;
        let (ys, yc) = self.yaw.to_radians().sin_cos();
        let (wx, wz) = ((x * yc - forward * ys) * t, (x * ys + forward * yc) * t);
        Some(((self.x + wx) / TEXTURE_SIDE_M, (self.z + wz) / TEXTURE_SIDE_M))
    }

    /// The feedback pass on the CPU, into `words`: derivatives from the neighbouring pixels (as
    /// `dpdx`/`dpdy`), the LOD biased by `bias` (the reduced size's plus the residency's).
    pub fn feedback(&self, grid: &TextureGrid, bias: f32, words: &mut Vec<u32>) {
        words.clear();
        for py in 0..FEEDBACK.1 {
            for px in 0..FEEDBACK.0 {
                let (px, py) = (px as f32 + 0.5, py as f32 + 0.5);
                let word = match (self.uv(px, py), self.uv(px + 1.0, py), self.uv(px, py + 1.0)) {
                    (Some((u, v)), Some((ux, vx)), Some((uy, vy))) => {
                        let lod = lod_for(ux - u, vx - v, uy - u, vy - v, [SIDE_TEXELS; 2], bias, grid.lod_count());
                        let side = SIDE_TEXELS as u32;
                        let payload = side / u32::from(grid.pages()[0]);
                        let at = uv_at(u.rem_euclid(1.0), v.rem_euclid(1.0), lod, [side, side], payload);
                        encode(PageId::new(0, lod, at.page[0] as u16, at.page[1] as u16), grid)
                    }
                    _ => NO_REQUEST,
                };
                words.push(word);
            }
        }
    }
}
