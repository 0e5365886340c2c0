//! Look-at poses: where the camera sits relative to the board, as a person describes a view.
//!
//! The camera is on a sphere of radius `distance` around the board centre, at `azimuth` about the
//! board's z axis (from its x axis) and `elevation` above the board plane (90° = straight above,
//! fronto-parallel), looking at the centre, with `roll` about the optical axis. At roll 0 the image
//! shows the board upright: image-down is the board's −y, image-right its +x when seen from above.
//! The result is `T_target_camera`; both setups turn it into a flange pose (see `plan`).

use nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use handeye_core::geometry::Pose;

/// A view of the board described from the board (angles in degrees for people).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LookAt {
    /// Distance from the camera to the board centre, m.
    pub distance: f64,
    /// Angle about the board z axis, from its x axis, degrees.
    pub azimuth_deg: f64,
    /// Angle above the board plane, degrees (90 = straight above).
    pub elevation_deg: f64,
    /// Rotation of the camera about its optical axis, degrees.
    #[serde(default)]
    pub roll_deg: f64,
    /// Where the board centre appears, degrees right (+) and down (+) of the optical axis
    /// (`[0, 0]`, the default: centred). Off-centre views put board corners across the image,
    /// which estimating the intrinsics (the distortion above all) needs.
    #[serde(default, skip_serializing_if = "is_centred")]
    pub board_in_image_deg: [f64; 2],
}

fn is_centred(offset: &[f64; 2]) -> bool {
    *offset == [0.0, 0.0]
}

impl LookAt {
    /// The camera pose in the board frame, `T_target_camera`, looking at `board_centre`
    /// (a point in the target frame).
    pub fn target_from_camera(&self, board_centre: &Point3<f64>) -> Pose {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        let direction = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        let camera_position = board_centre + direction * self.distance;
        let z_axis = -direction;
        // "Up" on the board is +y; near-grazing views along y fall back to x so the frame exists.
        let board_up = if Vector3::y().cross(&z_axis).norm() > 1e-6 {
            Vector3::y()
        } else {
            Vector3::x()
        };
        let y_axis = -(board_up - z_axis * board_up.dot(&z_axis)).normalize();
        let x_axis = y_axis.cross(&z_axis);
        let looking =
            Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x_axis, y_axis, z_axis]));
        let rolled = UnitQuaternion::from_rotation_matrix(&looking)
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.roll_deg.to_radians());
        // Turn the camera so the centre appears at `board_in_image_deg`: `aside` takes the
        // optical axis to that direction, and the camera turns by its inverse.
        let [right, down] = self.board_in_image_deg.map(f64::to_radians);
        let seen_at = Vector3::new(right.tan(), down.tan(), 1.0);
        let aside = UnitQuaternion::rotation_between(&Vector3::z(), &seen_at)
            .unwrap_or_else(UnitQuaternion::identity);
        Pose::from_parts(
            Translation3::from(camera_position.coords),
            rolled * aside.inverse(),
        )
    }

    /// Checks the numbers make a view: a positive finite distance and finite angles, elevation in (0, 90].
    pub fn validate(&self) -> Result<(), String> {
        if !(self.distance.is_finite() && self.distance > 0.0) {
            return Err(format!(
                "distance must be a positive number of metres, got {}",
                self.distance
            ));
        }
        for (name, v) in [
            ("azimuth_deg", self.azimuth_deg),
            ("roll_deg", self.roll_deg),
        ] {
            if !v.is_finite() {
                return Err(format!(
                    "{name} must be a finite number of degrees, got {v}"
                ));
            }
        }
        if !self
            .board_in_image_deg
            .iter()
            .all(|v| v.is_finite() && v.abs() < 60.0)
        {
            return Err(format!(
                "board_in_image_deg must be two angles within ±60°, got {:?}",
                self.board_in_image_deg
            ));
        }
        if !(self.elevation_deg > 0.0 && self.elevation_deg <= 90.0) {
            return Err(format!(
                "elevation_deg must be in (0, 90] (90 = straight above the board), got {}",
                self.elevation_deg
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_above_sees_the_board_upright_at_the_distance() {
        let centre = Point3::new(0.1, 0.2, 0.0);
        let view = LookAt {
            distance: 0.6,
            azimuth_deg: 0.0,
            elevation_deg: 90.0,
            roll_deg: 0.0,
            board_in_image_deg: [0.0, 0.0],
        };
        let target_from_camera = view.target_from_camera(&centre);
        let camera_from_target = target_from_camera.inverse();
        let centre_in_camera = camera_from_target * centre;
        assert!((centre_in_camera - Point3::new(0.0, 0.0, 0.6)).norm() < 1e-12);
        // Board +x appears to the right (camera +x), board +y appears up (camera −y).
        let x_in_camera = camera_from_target.rotation * Vector3::x();
        let y_in_camera = camera_from_target.rotation * Vector3::y();
        assert!((x_in_camera - Vector3::x()).norm() < 1e-12);
        assert!((y_in_camera + Vector3::y()).norm() < 1e-12);
    }

    #[test]
    fn an_offset_view_sees_the_centre_where_asked() {
        let centre = Point3::new(0.14, 0.14, 0.0);
        for (right, down) in [(15.0, 0.0), (0.0, -10.0), (-20.0, 12.0)] {
            let view = LookAt {
                distance: 0.6,
                azimuth_deg: 30.0,
                elevation_deg: 70.0,
                roll_deg: 10.0,
                board_in_image_deg: [right, down],
            };
            view.validate().unwrap();
            let target_from_camera = view.target_from_camera(&centre);
            let c = target_from_camera.inverse() * centre;
            assert!((c.x / c.z - f64::tan(right.to_radians())).abs() < 1e-12);
            assert!((c.y / c.z - f64::tan(down.to_radians())).abs() < 1e-12);
            // Same camera position as the centred view: only the camera turned.
            let centred = LookAt {
                board_in_image_deg: [0.0, 0.0],
                ..view
            };
            let p = centred.target_from_camera(&centre).translation.vector;
            assert!((target_from_camera.translation.vector - p).norm() < 1e-12);
        }
        let bad = LookAt {
            distance: 0.6,
            azimuth_deg: 0.0,
            elevation_deg: 90.0,
            roll_deg: 0.0,
            board_in_image_deg: [75.0, 0.0],
        };
        assert!(bad.validate().unwrap_err().contains("board_in_image_deg"));
    }

    #[test]
    fn every_view_looks_at_the_centre() {
        let centre = Point3::new(0.14, 0.14, 0.0);
        for (az, el, roll) in [
            (0.0, 60.0, 0.0),
            (135.0, 45.0, 20.0),
            (-90.0, 75.0, -30.0),
            (90.0, 30.0, 0.0),
        ] {
            let view = LookAt {
                distance: 0.5,
                azimuth_deg: az,
                elevation_deg: el,
                roll_deg: roll,
                board_in_image_deg: [0.0, 0.0],
            };
            let camera_from_target = view.target_from_camera(&centre).inverse();
            let c = camera_from_target * centre;
            assert!(c.x.abs() < 1e-12 && c.y.abs() < 1e-12 && (c.z - 0.5).abs() < 1e-12);
            // Tilt between optical axis and board normal is 90° − elevation.
            let normal_in_camera = camera_from_target.rotation * Vector3::z();
            let tilt = (-normal_in_camera.z).acos().to_degrees();
            assert!(
                (tilt - (90.0 - el)).abs() < 1e-9,
                "az {az} el {el}: tilt {tilt}"
            );
        }
    }
}
