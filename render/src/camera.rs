//! The orbit camera and rays through pixels, for drawing and picking.

use glam::{Mat4, Vec3, Vec4};

/// Nearest allowed pitch from the poles, in radians, so the view never flips.
pub const PITCH_MARGIN_RADIANS: f32 = 0.01;
/// Narrowest field of view, and its distance from pi for the widest, in radians.
pub const MIN_FOV_Y_RADIANS: f32 = 0.01;
/// Smallest near clipping distance in world units.
pub const MIN_NEAR: f32 = 1e-4;
/// Closest allowed orbit distance, in world units.
pub const MIN_DISTANCE: f32 = 1e-3;

/// A camera orbiting `target` at `distance`, turned by `yaw` about +z and tilted by `pitch`.
///
/// World space is right-handed with +z up. Yaw 0 and pitch 0 place the eye on the -y side of
/// the target, looking towards +y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// The point looked at and orbited.
    pub target: Vec3,
    /// Rotation about +z in radians.
    pub yaw: f32,
    /// Elevation in radians, positive looks down from above.
    pub pitch: f32,
    /// Distance from eye to target in world units.
    pub distance: f32,
    /// Vertical field of view in radians.
    pub fov_y: f32,
    /// Near clipping distance.
    pub near: f32,
    /// Far clipping distance.
    pub far: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            target: Vec3::ZERO,
            yaw: 0.6,
            pitch: 0.45,
            distance: 4.0,
            fov_y: 0.8,
            near: 0.05,
            far: 100.0,
        }
    }
}

/// A half-line `origin + t * direction`, t >= 0, with unit `direction`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: Vec3,
    /// Unit direction.
    pub direction: Vec3,
}

impl Camera {
    /// Turns the camera by pixel-free angles and clamps the pitch short of the poles.
    pub fn orbit(&mut self, d_yaw: f32, d_pitch: f32) {
        let limit = std::f32::consts::FRAC_PI_2 - PITCH_MARGIN_RADIANS;
        self.yaw = (self.yaw + d_yaw).rem_euclid(std::f32::consts::TAU);
        self.pitch = (self.pitch + d_pitch).clamp(-limit, limit);
    }

    /// Multiplies the distance by `factor` (below 1 zooms in).
    pub fn zoom(&mut self, factor: f32) {
        if factor.is_finite() && factor > 0.0 {
            self.distance = (self.distance * factor).max(MIN_DISTANCE);
        }
    }

    /// The eye position in world space.
    pub fn eye(&self) -> Vec3 {
        let (sy, cy) = self.yaw.sin_cos();
        let (sp, cp) = self.pitch.sin_cos();
        self.target + self.distance * Vec3::new(sy * cp, -cy * cp, sp)
    }

    /// The world-from-camera inverse: camera space has the eye at the origin looking along -z.
    pub fn view(&self) -> Mat4 {
        glam::camera::rh::view::look_at_mat4(self.eye(), self.target, Vec3::Z)
    }

    /// The projection for an aspect ratio (width / height), depth 0..1 as wgpu expects.
    pub fn projection(&self, aspect: f32) -> Mat4 {
        // Clamp user-set fields so a bad camera gives a bad picture, never NaN or a panic.
        let fov_y = self
            .fov_y
            .clamp(MIN_FOV_Y_RADIANS, std::f32::consts::PI - MIN_FOV_Y_RADIANS);
        let near = self.near.max(MIN_NEAR);
        let far = self.far.max(2.0 * near);
        glam::camera::rh::proj::directx::perspective(fov_y, aspect.max(f32::EPSILON), near, far)
    }

    /// Projection times view.
    pub fn view_projection(&self, aspect: f32) -> Mat4 {
        self.projection(aspect) * self.view()
    }

    /// The ray from the eye through pixel `px` (x right, y down, in pixels) of a
    /// `size`-pixel viewport; pixel centres are at half-integers.
    pub fn ray_through_pixel(&self, px: [f32; 2], size: [u32; 2]) -> Ray {
        let (w, h) = (size[0].max(1) as f32, size[1].max(1) as f32);
        let ndc_x = 2.0 * px[0] / w - 1.0;
        let ndc_y = 1.0 - 2.0 * px[1] / h;
        let inv = self.view_projection(w / h).inverse();
        let unproject = |z: f32| {
            let p: Vec4 = inv * Vec4::new(ndc_x, ndc_y, z, 1.0);
            p.truncate() / p.w
        };
        let (near, far) = (unproject(0.0), unproject(1.0));
        Ray {
            origin: near,
            direction: (far - near).normalize_or(Vec3::NEG_Z),
        }
    }

    /// The pixel (x right, y down) where a world point appears, `None` behind the eye.
    pub fn project(&self, p: Vec3, size: [u32; 2]) -> Option<[f32; 2]> {
        let (w, h) = (size[0].max(1) as f32, size[1].max(1) as f32);
        let clip = self.view_projection(w / h) * p.extend(1.0);
        (clip.w > 0.0).then(|| {
            [
                (clip.x / clip.w + 1.0) * 0.5 * w,
                (1.0 - clip.y / clip.w) * 0.5 * h,
            ]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_through_the_centre_hits_the_target_and_projection_inverts_it() {
        let cam = Camera {
            yaw: 1.1,
            pitch: -0.3,
            target: Vec3::new(1.0, 2.0, 3.0),
            ..Camera::default()
        };
        let size = [640, 480];
        let ray = cam.ray_through_pixel([320.0, 240.0], size);
        let to_target = (cam.target - ray.origin).normalize();
        assert!(ray.direction.dot(to_target) > 0.99999, "{ray:?}");
        let p = Vec3::new(1.3, 1.8, 3.2);
        let px = cam.project(p, size).unwrap();
        let back = cam.ray_through_pixel(px, size);
        let along = (p - back.origin).normalize();
        assert!(back.direction.dot(along) > 0.99999);
    }

    #[test]
    fn orbit_clamps_pitch_and_zoom_keeps_distance_positive() {
        let mut cam = Camera::default();
        cam.orbit(0.0, 10.0);
        assert!(cam.pitch < std::f32::consts::FRAC_PI_2);
        assert!(cam.view().is_finite());
        cam.zoom(0.0);
        cam.zoom(1e-9);
        assert!(cam.distance >= MIN_DISTANCE);
        let eye_dist = (cam.eye() - cam.target).length();
        assert!((eye_dist - cam.distance).abs() < 1e-5);
    }
}
