//! The degrees of freedom of `mfd-station-uncertainty/1`
//! (`interchange.md`): each a small change applied to a station, exactly
//! as the spec's table defines it. Error budgets perturb a station along
//! them; a calibration estimates them and reports their covariance.

use nalgebra::{Rotation3, Unit, Vector3};

use super::{Distortion, Station};

macro_rules! dofs {
    ($($v:ident = $name:literal),* $(,)?) => {
        /// One degree of freedom of a station (the spec's table, in its order).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Dof { $(#[doc = $name] $v),* }

        impl Dof {
            /// Every degree of freedom, in the spec's order.
            pub const ALL: [Dof; [$($name),*].len()] = [$(Dof::$v),*];

            /// The spec's name, e.g. `camera.z_mm`.
            pub fn name(self) -> &'static str {
                match self { $(Dof::$v => $name),* }
            }
        }
    };
}

dofs! {
    CameraX = "camera.x_mm", CameraY = "camera.y_mm", CameraZ = "camera.z_mm",
    CameraRx = "camera.rx_deg", CameraRy = "camera.ry_deg", CameraRz = "camera.rz_deg",
    FocalLength = "camera.focal_length_mm", Cx = "camera.cx_px", Cy = "camera.cy_px",
    K1 = "camera.k1", K2 = "camera.k2", K3 = "camera.k3", P1 = "camera.p1", P2 = "camera.p2",
    ScreenX = "screen.x_mm", ScreenY = "screen.y_mm", ScreenZ = "screen.z_mm",
    ScreenRx = "screen.rx_deg", ScreenRy = "screen.ry_deg", ScreenRz = "screen.rz_deg",
    ScreenPitch = "screen.pixel_pitch_mm",
    ElementX = "element.x_mm", ElementY = "element.y_mm", ElementZ = "element.z_mm",
    ElementRx = "element.rx_deg", ElementRy = "element.ry_deg",
    Thickness = "element.thickness_mm", RefractiveIndex = "element.refractive_index",
}

impl Dof {
    /// The degree of freedom of a spec name, `None` for any other string.
    pub fn parse(name: &str) -> Option<Dof> {
        Dof::ALL.into_iter().find(|d| d.name() == name)
    }
}

fn axis(k: usize) -> Unit<Vector3<f64>> {
    [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()][k]
}

impl Station {
    /// This station with `dof` changed by `delta` (in the unit its name
    /// gives), exactly as the spec's table says. The result is not
    /// re-validated: a budget's small changes keep a station possible.
    pub fn perturbed(&self, dof: Dof, delta: f64) -> Station {
        use Dof::*;
        let mut s = self.clone();
        let turn = |k: usize| Rotation3::from_axis_angle(&axis(k), delta.to_radians());
        match dof {
            CameraX | CameraY | CameraZ => s.camera.position_mm[dof as usize] += delta,
            CameraRx | CameraRy | CameraRz => {
                let r = turn(dof as usize - CameraRx as usize);
                s.camera.world_from_camera = r * s.camera.world_from_camera;
            }
            FocalLength => s.camera.focal_length_mm += delta,
            Cx => s.camera.principal_point_px.x += delta,
            Cy => s.camera.principal_point_px.y += delta,
            K1 | K2 | K3 | P1 | P2 => {
                let mut d = s.camera.distortion.unwrap_or(Distortion {
                    k: [0.0; 3],
                    p: [0.0; 2],
                });
                match dof {
                    K1 | K2 | K3 => d.k[dof as usize - K1 as usize] += delta,
                    _ => d.p[dof as usize - P1 as usize] += delta,
                }
                s.camera.distortion = (!d.is_zero()).then_some(d);
            }
            ScreenX | ScreenY | ScreenZ => {
                s.screen.origin_mm[dof as usize - ScreenX as usize] += delta;
            }
            ScreenRx | ScreenRy | ScreenRz => {
                let r = turn(dof as usize - ScreenRx as usize);
                let q = s.screen.centre();
                s.screen.origin_mm = q + r * (s.screen.origin_mm - q);
                s.screen.u_axis = r * s.screen.u_axis;
                s.screen.v_axis = r * s.screen.v_axis;
            }
            ScreenPitch => {
                let q = s.screen.centre();
                s.screen.pixel_pitch_mm += delta;
                let half = (f64::from(s.screen.width) / 2.0) * s.screen.u_axis.as_ref()
                    + (f64::from(s.screen.height) / 2.0) * s.screen.v_axis.as_ref();
                s.screen.origin_mm = q - s.screen.pixel_pitch_mm * half;
            }
            ElementX | ElementY | ElementZ => {
                s.element.pose.offset_mm[dof as usize - ElementX as usize] += delta;
            }
            ElementRx | ElementRy => {
                s.element.pose.tilt_deg[dof as usize - ElementRx as usize] += delta;
            }
            Thickness => s.element.thickness_mm += delta,
            RefractiveIndex => s.element.refractive_index += delta,
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::station::bench_station;

    #[test]
    fn names_are_the_specs_and_parse_back() {
        assert_eq!(Dof::ALL.len(), 28);
        for d in Dof::ALL {
            assert_eq!(Dof::parse(d.name()), Some(d));
        }
        assert_eq!(Dof::parse("camera.z"), None);
        assert_eq!(Dof::ScreenPitch.name(), "screen.pixel_pitch_mm");
    }

    #[test]
    fn each_change_is_the_specs() {
        let s = bench_station(10.0, 1.5, 15.0).unwrap();
        let cz = s.perturbed(Dof::CameraZ, 0.5);
        assert_eq!(cz.camera.position_mm.z, s.camera.position_mm.z + 0.5);
        // A camera turn keeps the projection centre.
        let rz = s.perturbed(Dof::CameraRz, 0.01);
        assert_eq!(rz.camera.position_mm, s.camera.position_mm);
        let angle = (rz.camera.world_from_camera * s.camera.world_from_camera.inverse()).angle();
        assert!((angle - 0.01_f64.to_radians()).abs() < 1e-12);
        // A screen turn and a pitch change keep the screen's centre.
        for (d, v) in [(Dof::ScreenRx, 0.2), (Dof::ScreenPitch, 0.001)] {
            let t = s.perturbed(d, v);
            assert!(
                (t.screen.centre() - s.screen.centre()).norm() < 1e-9,
                "{d:?}"
            );
        }
        let k1 = s.perturbed(Dof::K1, -0.12);
        assert_eq!(k1.camera.distortion.unwrap().k, [-0.12, 0.0, 0.0]);
        let ry = s.perturbed(Dof::ElementRy, 1.0);
        assert_eq!(ry.element.pose.tilt_deg, [0.0, 1.0]);
        assert_eq!(
            s.perturbed(Dof::Thickness, 0.002).element.thickness_mm,
            10.002
        );
    }
}
