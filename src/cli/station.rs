//! `mfd station`: build a station file from hardware profiles.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use nalgebra::Point2;

use mfd::optics::outline::Shape;
use mfd::optics::station::{
    CameraProfile, DisplayProfile, Element, Pose, Station, SymmetricLayout, Wedge,
};

/// Arguments of `mfd station`.
#[derive(Args)]
pub struct StationArgs {
    /// Camera profile (hw/camera/*.toml).
    #[arg(long, default_value = "hw/camera/baumer-txg12.toml")]
    camera: PathBuf,
    /// Display profile (hw/display/*.toml).
    #[arg(long, default_value = "hw/display/mtiph-e2m21gm.toml")]
    display: PathBuf,
    /// Lens focal length, mm.
    #[arg(long, value_parser = super::check::positive, default_value_t = 16.0)]
    focal_length_mm: f64,
    /// Height of the camera's projection centre above the element, mm.
    #[arg(long, value_parser = super::check::positive, default_value_t = 825.0)]
    camera_height_mm: f64,
    /// Height of the screen above the element, mm.
    #[arg(long, value_parser = super::check::positive, default_value_t = 825.0)]
    screen_height_mm: f64,
    /// Angle between the camera's axis and the element's normal, degrees
    /// (in the x–z plane; the screen sits at the mirror angle).
    #[arg(long, value_parser = super::check::range(-89.0, 89.0, "degrees from the element's normal"), default_value_t = 15.0)]
    tilt_deg: f64,
    /// Refractive index of the element.
    #[arg(long, value_parser = super::check::refractive_index, default_value_t = 1.5)]
    refractive_index: f64,
    /// Element thickness, mm.
    #[arg(long, value_parser = super::check::positive, default_value_t = 10.0)]
    thickness_mm: f64,
    /// Radius of the measured aperture, mm.
    #[arg(long, value_parser = super::check::positive, default_value_t = 25.5)]
    aperture_radius_mm: f64,
    /// The element's tilt about world x, then y, degrees (`element.tilt_deg`
    /// of `mfd-station/2`: an element mounted at an angle to the reference plane).
    #[arg(long, value_parser = super::check::range(-45.0, 45.0, "degrees of tilt"), value_delimiter = ',', num_args = 2, default_values_t = [0.0, 0.0])]
    element_tilt_deg: Vec<f64>,
    /// The wedge the plate was made with, arcmin (`element.wedge_arcmin` of
    /// `mfd-station/2`: the angle between its faces; at most 120).
    #[arg(long, value_parser = super::check::range(0.0, 120.0, "arcmin of wedge"), default_value_t = 0.0)]
    wedge_arcmin: f64,
    /// The direction in the element's frame along which the plate thins,
    /// degrees (`element.wedge_azimuth_deg`).
    #[arg(long, value_parser = super::check::range(-360.0, 360.0, "degrees of azimuth"), default_value_t = 0.0, allow_negative_numbers = true)]
    wedge_azimuth_deg: f64,
    /// A rectangular element: its sides along x and y, mm (the proposal
    /// `mfd-station/3`'s `[element.outline]`, docs/proposals/outline.md).
    /// The aperture radius becomes the rectangle's half-diagonal: the
    /// least Zernike disk that contains it.
    #[arg(long, value_parser = super::check::positive, value_delimiter = ',', num_args = 1)]
    rectangle_mm: Option<Vec<f64>>,
    /// The rectangle's rotation about the aperture centre, degrees from +x
    /// towards +y.
    #[arg(long, value_parser = super::check::range(-360.0, 360.0, "degrees of rotation"), default_value_t = 0.0, allow_negative_numbers = true, requires = "rectangle_mm")]
    rectangle_rotation_deg: f64,
    /// The camera's fy / fx (the proposal `mfd-station/3`'s
    /// `camera.aspect_ratio`, docs/proposals/aspect.md): from a calibration
    /// by OpenCV or OpenCSP, fy divided by fx. Declared, a calibration
    /// estimates it; absent, the pixels are square.
    #[arg(long, value_parser = super::check::range(mfd::optics::station::ASPECT_RANGE[0], mfd::optics::station::ASPECT_RANGE[1], "fy / fx"))]
    aspect_ratio: Option<f64>,
    /// Where to write the station.toml.
    #[arg(long)]
    out: PathBuf,
}

/// Runs `mfd station`.
pub fn run(args: &StationArgs) -> anyhow::Result<()> {
    let camera = CameraProfile::load(&args.camera)?;
    let display = DisplayProfile::load(&args.display)?;
    let layout = SymmetricLayout {
        camera_height_mm: args.camera_height_mm,
        screen_height_mm: args.screen_height_mm,
        tilt_deg: args.tilt_deg,
        focal_length_mm: args.focal_length_mm,
        element: Element {
            refractive_index: args.refractive_index,
            thickness_mm: args.thickness_mm,
            aperture_radius_mm: args.aperture_radius_mm,
            aperture_center_mm: Point2::origin(),
            pose: Pose::default(),
            wedge: Wedge {
                arcmin: args.wedge_arcmin,
                azimuth_deg: args.wedge_azimuth_deg,
            },
            outline: Shape::Circle,
        },
    };
    let mut station = layout.build(&camera, &display)?;
    if let [rx, ry] = args.element_tilt_deg[..] {
        station.element.pose.tilt_deg = [rx, ry];
    }
    if let Some(v) = args.rectangle_mm.as_deref() {
        let &[a, b] = v else {
            return Err(super::exit::usage(anyhow::anyhow!(
                "--rectangle-mm: expected two sides A,B in mm, found {} values",
                v.len()
            )));
        };
        station.element.outline = Shape::Rectangle {
            sides_mm: [a, b],
            rotation_deg: args.rectangle_rotation_deg,
        };
        let half_diagonal = a.hypot(b) / 2.0;
        station.element.aperture_radius_mm = half_diagonal;
    }
    station.camera.aspect_ratio = args.aspect_ratio;
    if station.needs_version_2() || station.needs_version_3() {
        // Through the file form: a tilted or wedged element is checked as a loaded one is.
        station = Station::from_file(&station.to_file(), &args.out)?;
    }
    let header = format!(
        "# Built by `mfd station` from {} and {}:\n# camera {} mm and screen {} mm above the \
         element, axis {}° from the normal, f = {} mm.\n",
        args.camera.display(),
        args.display.display(),
        args.camera_height_mm,
        args.screen_height_mm,
        args.tilt_deg,
        args.focal_length_mm
    );
    std::fs::write(&args.out, header + &station.to_toml_string())
        .with_context(|| format!("writing {}", args.out.display()))?;
    println!("wrote {}", args.out.display());
    Ok(())
}
