//! Opening the camera a [`CameraSpec`] names: the simulated station's
//! camera for `sim`, the simulated station served over GigE Vision on
//! loopback for `aravis:fake` ([`crate::sim::aravis_fake`]), real devices
//! through their backends in [`crate::acquire::camera`]. Here, above both
//! `acquire` and `sim`, so that neither needs the other.

#[cfg(feature = "aravis")]
use crate::acquire::camera::aravis;
#[cfg(feature = "v4l")]
use crate::acquire::camera::v4l;
use crate::acquire::camera::{Camera, CameraError, CameraSpec};
#[cfg(feature = "aravis")]
use crate::sim::aravis_fake;
use crate::sim::{SimulatedCamera, SpotCamera};

/// Opens the camera `spec` names. `sim` is the simulated camera, used for
/// [`CameraSpec::Sim`] and served by the Aravis fake camera for
/// `aravis:fake`; real devices ignore it.
///
/// # Errors
/// [`CameraError::NotBuilt`] when the backend's feature is off;
/// [`CameraError::BadSpec`] when a simulated camera is needed and none was
/// given; device errors.
pub fn open(
    spec: &CameraSpec,
    sim: Option<SimulatedCamera>,
) -> Result<Box<dyn Camera>, CameraError> {
    let need_sim = || CameraError::BadSpec {
        spec: format!("{spec:?}"),
        problem: "a simulated station is needed (give --sim-surfaces or a station)".into(),
    };
    match spec {
        CameraSpec::Sim => Ok(Box::new(sim.ok_or_else(need_sim)?)),
        #[cfg(feature = "aravis")]
        CameraSpec::Aravis(Some(id)) if id == "fake" => {
            let sim = sim.ok_or_else(need_sim)?;
            Ok(Box::new(aravis_fake::FakeStation::start(sim)?))
        }
        #[cfg(feature = "aravis")]
        CameraSpec::Aravis(id) => Ok(Box::new(aravis::AravisCamera::open(id.as_deref())?)),
        #[cfg(not(feature = "aravis"))]
        CameraSpec::Aravis(_) => Err(CameraError::NotBuilt {
            backend: "aravis".into(),
            feature: "aravis",
        }),
        #[cfg(feature = "v4l")]
        CameraSpec::V4l(dev) => Ok(Box::new(v4l::V4lCamera::open(dev)?)),
        #[cfg(not(feature = "v4l"))]
        CameraSpec::V4l(_) => Err(CameraError::NotBuilt {
            backend: "v4l".into(),
            feature: "v4l",
        }),
    }
}

/// Opens the camera `spec` names for a calibration target: `sim` is
/// `target` itself, `aravis:fake` serves `target`'s frames over GigE Vision
/// on loopback, real devices ignore it.
///
/// # Errors
/// As [`open`].
pub fn open_for_target(
    spec: &CameraSpec,
    target: SpotCamera,
) -> Result<Box<dyn Camera>, CameraError> {
    match spec {
        CameraSpec::Sim => Ok(Box::new(target)),
        #[cfg(feature = "aravis")]
        CameraSpec::Aravis(Some(id)) if id == "fake" => {
            Ok(Box::new(aravis_fake::FakeStation::start_target(target)?))
        }
        real => open(real, None),
    }
}

// With both backends built there is nothing here to test.
#[cfg(all(test, not(all(feature = "v4l", feature = "aravis"))))]
mod tests {
    use super::*;

    #[cfg(not(feature = "v4l"))]
    #[test]
    fn a_backend_not_built_names_its_feature() {
        let err = match open(&CameraSpec::V4l("/dev/video0".into()), None) {
            Err(e) => e,
            Ok(_) => panic!("v4l opened without the feature"),
        };
        assert!(matches!(err, CameraError::NotBuilt { feature: "v4l", .. }));
        assert!(err.to_string().contains("--features v4l"), "{err}");
    }

    #[cfg(not(feature = "aravis"))]
    #[test]
    fn aravis_not_built_names_its_feature() {
        let err = match open(&CameraSpec::Aravis(None), None) {
            Err(e) => e,
            Ok(_) => panic!("aravis opened without the feature"),
        };
        assert!(err.to_string().contains("--features aravis"), "{err}");
    }
}
