//! The 3D view's orbit camera: view-projection matrix (wgpu clip space, depth 0..1) and mouse handling
//! (drag: orbit, right/middle drag: pan, scroll: zoom).

use glam::{Mat4, Vec3};

use crate::state::OrbitCamera;

/// Vertical field of view, radians.
const FOV_Y: f32 = 0.75;

/// Eye position and view-projection matrix for coordinates relative to the scene centre.
pub fn view_proj(cam: &OrbitCamera, aspect: f32) -> (Vec3, Mat4) {
    let target = glam::DVec3::from_array(cam.pan).as_vec3();
    let (yaw, pitch, dist) = (cam.yaw as f32, cam.pitch as f32, cam.distance as f32);
    let dir = Vec3::new(
        pitch.cos() * yaw.cos(),
        pitch.cos() * yaw.sin(),
        pitch.sin(),
    );
    let eye = target + dir * dist;
    let view = glam::camera::rh::view::look_at_mat4(eye, target, Vec3::Z);
    let proj = glam::camera::rh::proj::directx::perspective(
        FOV_Y,
        aspect.max(1e-3),
        dist * 0.02,
        dist * 20.0,
    );
    (eye, proj * view)
}

/// Apply this frame's mouse input on `response` to the camera; returns true when it moved.
pub fn handle_input(cam: &mut OrbitCamera, response: &egui::Response, ui: &egui::Ui) -> bool {
    let before = *cam;
    let delta = response.drag_delta();
    if response.dragged_by(egui::PointerButton::Primary) {
        cam.yaw -= f64::from(delta.x) * 0.01;
        cam.pitch = (cam.pitch + f64::from(delta.y) * 0.01).clamp(-1.5, 1.5);
    } else if response.dragged_by(egui::PointerButton::Secondary)
        || response.dragged_by(egui::PointerButton::Middle)
    {
        let (yaw, pitch) = (cam.yaw, cam.pitch);
        let right = glam::DVec3::new(-yaw.sin(), yaw.cos(), 0.0);
        let forward = glam::DVec3::new(
            pitch.cos() * yaw.cos(),
            pitch.cos() * yaw.sin(),
            pitch.sin(),
        );
        let up = forward.cross(right);
        let k = cam.distance * 0.0015;
        let pan = glam::DVec3::from_array(cam.pan) + right * f64::from(delta.x) * k
            - up * f64::from(delta.y) * k;
        cam.pan = pan.to_array();
    }
    if response.hovered() {
        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
        if scroll != 0.0 {
            cam.distance = (cam.distance * (-f64::from(scroll) * 0.002).exp()).clamp(0.02, 2.0);
        }
    }
    *cam != before
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_projects_to_the_view_centre_in_front_of_the_camera() {
        let cam = OrbitCamera {
            pan: [0.01, -0.02, 0.005],
            ..Default::default()
        };
        let (eye, m) = view_proj(&cam, 1.5);
        let c = m.project_point3(Vec3::new(0.01, -0.02, 0.005));
        assert!(
            c.x.abs() < 1e-5 && c.y.abs() < 1e-5 && c.z > 0.0 && c.z < 1.0,
            "{c}"
        );
        assert!((eye - Vec3::new(0.01, -0.02, 0.005)).length() - 0.30 < 1e-5);
        // A point above the target appears above the centre (y up in NDC).
        assert!(m.project_point3(Vec3::new(0.01, -0.02, 0.02)).y > 0.0);
    }
}
