//! Pinhole camera: where the eye is, where it looks and its vertical field of view.

use glam::Vec3;

use super::geometry::orthogonal_up;
use super::SceneError;

const CLI_FORM: &str = "px,py,pz:tx,ty,tz:fov_deg (e.g. 0,0.1,1.2:0,0.1,0:30)";

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    /// Unit.
    pub forward: Vec3,
    /// Unit, orthogonal to `forward`.
    pub up: Vec3,
    pub yfov_deg: f32,
}

impl Camera {
    /// A camera at `position` looking at `target`, rolled so that world +Y is up (+Z when
    /// looking straight along Y, where +Y gives no roll information).
    pub fn look_at(position: Vec3, target: Vec3, yfov_deg: f32) -> Result<Camera, SceneError> {
        if !position.is_finite() || !target.is_finite() {
            return Err(SceneError::BadCamera {
                reason: format!("position {position} and target {target} must be finite"),
            });
        }
        if !(yfov_deg > 0.0 && yfov_deg < 180.0) {
            return Err(SceneError::BadCamera {
                reason: format!("vertical field of view {yfov_deg}° must be in (0, 180) degrees"),
            });
        }
        let forward = (target - position).normalize_or_zero();
        if forward == Vec3::ZERO {
            return Err(SceneError::BadCamera {
                reason: format!("position and target are both {position}; move one of them"),
            });
        }
        Ok(Camera {
            position,
            forward,
            up: orthogonal_up(forward, Vec3::Y),
            yfov_deg,
        })
    }

    /// Parses the `--camera` flag: "px,py,pz:tx,ty,tz:fov_deg".
    pub fn parse_cli(s: &str) -> Result<Camera, SceneError> {
        let bad = |what: String| SceneError::BadCamera {
            reason: format!("--camera '{s}': {what}; expected {CLI_FORM}"),
        };
        let parts: Vec<&str> = s.trim().split(':').collect();
        let [pos, target, fov] = parts.as_slice() else {
            return Err(bad(format!(
                "found {} ':'-separated parts, need 3",
                parts.len()
            )));
        };
        let vec3 = |text: &str, name: &str| -> Result<Vec3, SceneError> {
            let comps: Vec<&str> = text.split(',').collect();
            if comps.len() != 3 {
                return Err(bad(format!(
                    "{name} '{text}' needs 3 comma-separated numbers"
                )));
            }
            let mut v = [0.0f32; 3];
            for (slot, c) in v.iter_mut().zip(&comps) {
                *slot = c
                    .trim()
                    .parse::<f32>()
                    .map_err(|_| bad(format!("{name} component '{c}' is not a number")))?;
            }
            Ok(Vec3::from(v))
        };
        let position = vec3(pos, "position")?;
        let target = vec3(target, "target")?;
        let fov: f32 = fov
            .trim()
            .parse()
            .map_err(|_| bad(format!("field of view '{fov}' is not a number")))?;
        Camera::look_at(position, target, fov).map_err(|e| match e {
            SceneError::BadCamera { reason } => bad(reason),
            other => other,
        })
    }

    /// Default framing: from +Z towards the bounds' centre, far enough that the bounding sphere
    /// fits the narrower of the vertical and horizontal fields of view, 30° vertical fov.
    pub fn frame_bounds(min: Vec3, max: Vec3, aspect: f32) -> Camera {
        const FOV_DEG: f32 = 30.0;
        let (min, max) = if min.is_finite() && max.is_finite() {
            (min, max)
        } else {
            (Vec3::splat(-0.5), Vec3::splat(0.5))
        };
        let centre = (min + max) * 0.5;
        // A zero-size box would put the eye inside it; keep a minimal working distance.
        let radius = ((max - min).length() * 0.5).max(1e-3);
        let aspect = if aspect.is_finite() && aspect > 0.0 {
            aspect
        } else {
            1.0
        };
        let half_v = (FOV_DEG * 0.5).to_radians();
        let half_h = (half_v.tan() * aspect).atan();
        let half = half_v.min(half_h);
        let distance = radius / half.sin();
        Camera {
            position: centre + Vec3::Z * distance,
            forward: -Vec3::Z,
            up: Vec3::Y,
            yfov_deg: FOV_DEG,
        }
    }
}
