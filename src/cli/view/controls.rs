//! How input moves the view: a 2D pan and zoom over one image (drag, wheel, arrows, + and -),
//! or a fly camera over the scene's geometry (W A S D, Q E, drag to look). Plain arithmetic on
//! the CPU, tested here; the window code only feeds it events.

use vortex_vt_wgpu::harness::camera::Camera;
use vortex_vt_wgpu::harness::{Pose, Window};

/// A 2D view of one texture: the image UV at the window's centre and the share of the image's
/// width it shows (square pixels).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PanZoom {
    pub texture: u8,
    pub center: [f64; 2],
    pub width: f64,
}

/// The most a view zooms in: this many pixels per LOD-0 texel.
const MOST_PIXELS_PER_TEXEL: f64 = 64.0;

impl PanZoom {
    /// The pose for a `size` window onto an image of `image` texels.
    pub fn pose(&self, image: [u32; 2], size: (u32, u32)) -> Pose {
        Pose::Window(Window::square_pixels(self.texture, image, self.center, self.width, size))
    }

    /// Moves the image by `pixels` (dragging it: the image follows the pointer).
    pub fn pan(&mut self, pixels: [f64; 2], image: [u32; 2], size: (u32, u32)) {
        let Pose::Window(w) = self.pose(image, size) else { return };
        self.center[0] -= pixels[0] * w.extent[0] / f64::from(size.0);
        self.center[1] -= pixels[1] * w.extent[1] / f64::from(size.1);
        self.center = self.center.map(|c| c.clamp(0.0, 1.0));
    }

    /// Zooms by `factor` (above 1: closer) keeping the image point under pixel `at` in place;
    /// from the whole image (at most twice its width across) to 64 pixels per texel.
    pub fn zoom(&mut self, factor: f64, at: [f64; 2], image: [u32; 2], size: (u32, u32)) {
        let Pose::Window(before) = self.pose(image, size) else { return };
        let anchor = [
            before.origin[0] + at[0] / f64::from(size.0) * before.extent[0],
            before.origin[1] + at[1] / f64::from(size.1) * before.extent[1],
        ];
        let least = f64::from(size.0) / MOST_PIXELS_PER_TEXEL / f64::from(image[0].max(1));
        let width = (self.width / factor).clamp(least, 2.0);
        let scale = width / self.width;
        self.width = width;
        self.center = [0, 1].map(|i| anchor[i] + (self.center[i] - anchor[i]) * scale);
    }
}

/// A free camera: where it is and where it looks (yaw about +y from -z, pitch up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fly {
    pub eye: [f32; 3],
    pub yaw: f32,
    pub pitch: f32,
    pub fov_y_deg: f32,
}

impl Fly {
    /// The camera at `camera`, looking at its target.
    pub fn looking(camera: Camera, fov_y_deg: f32) -> Fly {
        let d = [0, 1, 2].map(|i| camera.target[i] - camera.eye[i]);
        let horizontal = (d[0] * d[0] + d[2] * d[2]).sqrt();
        Fly { eye: camera.eye, yaw: d[0].atan2(-d[2]), pitch: d[1].atan2(horizontal), fov_y_deg }
    }

    /// The unit vector it looks along.
    pub fn forward(&self) -> [f32; 3] {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        [sy * cp, sp, -cy * cp]
    }

    pub fn pose(&self, size: (u32, u32)) -> Pose {
        let f = self.forward();
        let camera = Camera { eye: self.eye, target: [0, 1, 2].map(|i| self.eye[i] + f[i]) };
        Pose::Camera(camera.view_proj(self.fov_y_deg, size.0 as f32 / size.1.max(1) as f32))
    }

    /// Moves by `forward`, `right` and `up` units along its own axes (up is the world's).
    pub fn fly(&mut self, forward: f32, right: f32, up: f32) {
        let f = self.forward();
        let r = [-f[2], 0.0, f[0]];
        let norm = (r[0] * r[0] + r[2] * r[2]).sqrt().max(1e-6);
        for i in 0..3 {
            self.eye[i] += f[i] * forward + r[i] / norm * right;
        }
        self.eye[1] += up;
    }

    /// Turns by `pixels` of pointer movement.
    pub fn look(&mut self, pixels: [f64; 2]) {
        self.yaw += pixels[0] as f32 * 0.004;
        self.pitch = (self.pitch - pixels[1] as f32 * 0.004).clamp(-1.55, 1.55);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const IMAGE: [u32; 2] = [4000, 2000];
    const SIZE: (u32, u32) = (800, 600);

    #[test]
    fn zooming_keeps_the_point_under_the_pointer() {
        let mut v = PanZoom { texture: 0, center: [0.5, 0.5], width: 1.0 };
        let at = [200.0, 450.0];
        let uv = |v: &PanZoom| {
            let Pose::Window(w) = v.pose(IMAGE, SIZE) else { unreachable!() };
            [w.origin[0] + at[0] / 800.0 * w.extent[0], w.origin[1] + at[1] / 600.0 * w.extent[1]]
        };
        let before = uv(&v);
        v.zoom(3.0, at, IMAGE, SIZE);
        let after = uv(&v);
        assert!((before[0] - after[0]).abs() < 1e-12 && (before[1] - after[1]).abs() < 1e-12);
        assert!((v.width - 1.0 / 3.0).abs() < 1e-12);
        // Never closer than 64 pixels per texel.
        v.zoom(1e9, at, IMAGE, SIZE);
        assert!((v.width - 800.0 / 64.0 / 4000.0).abs() < 1e-15);
    }

    #[test]
    fn dragging_moves_the_image_with_the_pointer() {
        let mut v = PanZoom { texture: 0, center: [0.5, 0.5], width: 0.5 };
        v.pan([80.0, 0.0], IMAGE, SIZE);
        // 80 of 800 pixels over half the image's width: 0.05 of it, to the left.
        assert!((v.center[0] - 0.45).abs() < 1e-12 && v.center[1] == 0.5);
    }

    #[test]
    fn the_fly_camera_starts_looking_at_its_target_and_moves_along_its_axes() {
        let camera = Camera { eye: [0.0, 1.0, 1.0], target: [0.0, 0.0, 0.0] };
        let mut fly = Fly::looking(camera, 60.0);
        let f = fly.forward();
        let s = std::f32::consts::FRAC_1_SQRT_2;
        assert!((f[0]).abs() < 1e-6 && (f[1] + s).abs() < 1e-6 && (f[2] + s).abs() < 1e-6, "{f:?}");
        fly.fly(0.0, 1.0, 0.0);
        assert!((fly.eye[0] - 1.0).abs() < 1e-6 && (fly.eye[1] - 1.0).abs() < 1e-6, "{:?}", fly.eye);
    }
}
