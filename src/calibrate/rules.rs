//! The spec's rules for a session (`calibration.md`), each turned into a
//! [`SessionError`] naming the entry: [`validate`] lists every problem it
//! finds, in the order a person would fix them, so that
//! [`Session::load`](super::session::Session::load) can stop at the first
//! and the check can list them all.

use std::path::{Path, PathBuf};

use nalgebra::Point3;

use super::session::{folder_of, SessionError};
use super::session_file::{SessionElement, SessionFile, SESSION_FORMAT};
use super::spread::Spread;
use crate::optics::station::Station;

/// Plausible 1 σ of one PSM-and-encoder reading, µm. Below 10 nm no stage
/// and focus detector reads (a value like 0.001 is 1 µm written in mm);
/// above 100 µm the session cannot calibrate anything a measurement needs
/// (or the value is in nm).
pub const PLAUSIBLE_STAGE_STD_UM: std::ops::RangeInclusive<f64> = 0.01..=100.0;

/// A unit written wrongly scales readings by 1000 (µm or m for mm). A set
/// of readings is judged against the scale it must have with the margin
/// `√1000 ≈ 31.6` on either side: halfway, in log scale, between right and
/// wrong, so a real session is never flagged and a wrong unit always is.
pub const UNIT_MARGIN: f64 = 31.622_776_601_683_793;

/// Every problem of `file` (read from `path`), and the nominal station
/// where it loaded.
pub fn validate(file: &SessionFile, path: &Path) -> (Option<Station>, Vec<SessionError>) {
    let mut v = Rules {
        path,
        dir: folder_of(path),
        problems: Vec::new(),
    };
    if file.format != SESSION_FORMAT {
        v.invalid(
            "format",
            format!("\"{}\"", file.format),
            format!("\"{SESSION_FORMAT}\""),
            "this reader knows only that format".into(),
        );
    }
    v.scalars(file);
    v.entries(file);
    let nominal = v.files(file);
    if let Some(station) = &nominal {
        v.units(file, station);
    }
    v.counts_and_geometry(file);
    (nominal, v.problems)
}

struct Rules<'a> {
    path: &'a Path,
    dir: PathBuf,
    problems: Vec<SessionError>,
}

impl Rules<'_> {
    fn invalid(&mut self, entry: impl Into<String>, found: String, expected: String, todo: String) {
        self.problems.push(SessionError::Invalid {
            path: self.path.to_path_buf(),
            entry: entry.into(),
            found,
            expected,
            todo,
        });
    }

    fn positive(&mut self, entry: &str, value: f64, todo: &str) -> bool {
        let ok = value.is_finite() && value > 0.0;
        if !ok {
            self.invalid(
                entry,
                format!("{value}"),
                "a finite value > 0".into(),
                todo.into(),
            );
        }
        ok
    }

    fn scalars(&mut self, file: &SessionFile) {
        let std = file.stage_std_um;
        if self.positive("stage_std_um", std, "give 1 σ of one reading in µm")
            && !PLAUSIBLE_STAGE_STD_UM.contains(&std)
        {
            self.invalid(
                "stage_std_um",
                format!("{std} µm"),
                format!(
                    "{} to {} µm for a PSM on a stage",
                    PLAUSIBLE_STAGE_STD_UM.start(),
                    PLAUSIBLE_STAGE_STD_UM.end()
                ),
                "the value is in µm (1.0 means 1 µm): check its unit".into(),
            );
        }
        self.element(&file.element);
        let pv = file.reference_flat.flat_pv_nm;
        if !(pv.is_finite() && pv >= 0.0) {
            self.invalid(
                "reference_flat.flat_pv_nm",
                format!("{pv}"),
                "a finite flatness ≥ 0 nm PV".into(),
                "give the flat's certified flatness".into(),
            );
        }
    }

    fn element(&mut self, e: &SessionElement) {
        if !e.center_stage_mm.iter().all(|c| c.is_finite()) {
            self.invalid(
                "element.center_stage_mm",
                format!("{:?}", e.center_stage_mm),
                "finite stage x, y in mm".into(),
                "give the stage x, y of the element's centre".into(),
            );
        }
        let t = self.positive(
            "element.thickness_mm",
            e.thickness_mm,
            "give the measured thickness in mm",
        );
        let ts = self.positive(
            "element.thickness_std_mm",
            e.thickness_std_mm,
            "give its 1 σ in mm",
        );
        if t && ts && e.thickness_std_mm >= e.thickness_mm {
            self.invalid(
                "element.thickness_std_mm",
                format!("{} mm", e.thickness_std_mm),
                format!("well below the thickness, {} mm", e.thickness_mm),
                "give the spherometer's 1 σ".into(),
            );
        }
        let n = e.refractive_index;
        if !(n.is_finite() && n > 1.0) {
            self.invalid(
                "element.refractive_index",
                format!("{n}"),
                "a finite index > 1".into(),
                "give the refractometer's value at the screen's wavelength".into(),
            );
        }
        let ns = self.positive(
            "element.refractive_index_std",
            e.refractive_index_std,
            "give its 1 σ",
        );
        if ns && n > 1.0 && e.refractive_index_std >= n - 1.0 {
            self.invalid(
                "element.refractive_index_std",
                format!("{}", e.refractive_index_std),
                format!("well below n − 1 = {:.4}", n - 1.0),
                "give the refractometer's 1 σ".into(),
            );
        }
    }

    fn finite_point(&mut self, entry: String, p: [f64; 3]) {
        if !p.iter().all(|c| c.is_finite()) {
            self.invalid(
                entry,
                format!("{p:?}"),
                "three finite stage coordinates in mm".into(),
                "re-enter the stage reading".into(),
            );
        }
    }

    fn entries(&mut self, file: &SessionFile) {
        for (k, p) in file.flat_point.iter().enumerate() {
            self.finite_point(format!("flat_point[{k}].stage_mm"), p.stage_mm);
        }
        for (k, p) in file.element_point.iter().enumerate() {
            self.finite_point(format!("element_point[{k}].stage_mm"), p.stage_mm);
        }
        for (k, t) in file.target_point.iter().enumerate() {
            self.finite_point(format!("target_point[{k}].stage_mm"), t.stage_mm);
            let found = match (&t.image, &t.image_px) {
                (Some(_), Some(_)) => "both `image` and `image_px`",
                (None, None) => "neither `image` nor `image_px`",
                _ => "",
            };
            if !found.is_empty() {
                self.invalid(
                    format!("target_point[{k}]"),
                    found.into(),
                    "exactly one of them".into(),
                    "keep the camera frame (`image`) or the centroid (`image_px`), not both".into(),
                );
            }
            if let Some(px) = t.image_px.filter(|px| !px.iter().all(|c| c.is_finite())) {
                self.invalid(
                    format!("target_point[{k}].image_px"),
                    format!("{px:?}"),
                    "a finite centroid [x, y] in px".into(),
                    "re-enter the centroid".into(),
                );
            }
        }
        for (k, s) in file.screen_point.iter().enumerate() {
            self.finite_point(format!("screen_point[{k}].stage_mm"), s.stage_mm);
            if !s.screen_px.iter().all(|c| c.is_finite()) {
                self.invalid(
                    format!("screen_point[{k}].screen_px"),
                    format!("{:?}", s.screen_px),
                    "a finite (u, v) in screen px".into(),
                    "re-enter the mark's screen coordinate".into(),
                );
            }
        }
    }

    /// A path of the session, resolved, where it is relative and exists.
    fn file_path(&mut self, entry: String, rel: &str, todo: &str) -> Option<PathBuf> {
        if Path::new(rel).is_absolute() {
            self.invalid(
                entry,
                format!("the absolute path {rel}"),
                "a path relative to session.toml".into(),
                "keep the session's files in its folder and name them relatively".into(),
            );
            return None;
        }
        let file = self.dir.join(rel);
        if file.is_file() {
            Some(file)
        } else {
            self.problems.push(SessionError::MissingFile {
                path: self.path.to_path_buf(),
                entry,
                file,
                todo: todo.into(),
            });
            None
        }
    }

    fn files(&mut self, file: &SessionFile) -> Option<Station> {
        for (k, t) in file.target_point.iter().enumerate() {
            if let Some(image) = &t.image {
                self.file_path(
                    format!("target_point[{k}].image"),
                    image,
                    "capture it (`mfd calibrate capture`) or give `image_px`",
                );
            }
        }
        self.file_path(
            "reference_flat.acquisition".into(),
            &file.reference_flat.acquisition,
            "record the reference flat with `mfd measure --no-reconstruct --out` into the session folder",
        );
        let station = self.file_path(
            "nominal_station".into(),
            &file.nominal_station,
            "put the nominal station (`mfd station` builds one) in the session folder",
        )?;
        match Station::load(&station) {
            Ok(s) => Some(s),
            Err(source) => {
                self.problems.push(SessionError::Nominal {
                    path: self.path.to_path_buf(),
                    station,
                    source: Box::new(source),
                });
                None
            }
        }
    }

    fn units(&mut self, file: &SessionFile, station: &Station) {
        let readings = readings(file);
        let finite: Vec<_> = readings
            .iter()
            .filter(|(_, p)| p.iter().all(|c| c.is_finite()))
            .collect();
        if finite.len() < 2 {
            return;
        }
        let size_mm = station_size_mm(station);
        let aperture_mm = 2.0 * station.element.aperture_radius_mm;
        let pts: Vec<Point3<f64>> = finite.iter().map(|(_, p)| Point3::from(*p)).collect();
        let extent = extent_mm(&pts);
        if extent > UNIT_MARGIN * size_mm {
            let median = median_point(&pts);
            let (entry, p) = finite
                .iter()
                .max_by(|a, b| {
                    let da = (Point3::from(a.1) - median).norm();
                    let db = (Point3::from(b.1) - median).norm();
                    da.total_cmp(&db)
                })
                .map_or((String::new(), [0.0; 3]), |(e, p)| (e.clone(), *p));
            self.problems.push(SessionError::Units {
                path: self.path.to_path_buf(),
                entry,
                found: format!(
                    "{p:?}: the readings span {:.0} mm where the whole nominal station is {:.0} mm across",
                    extent, size_mm
                ),
                todo: "µm written for mm? divide by 1000".into(),
            });
        }
        let flat: Vec<Point3<f64>> = file
            .flat_point
            .iter()
            .map(|p| Point3::from(p.stage_mm))
            .collect();
        if flat.len() >= 2 && extent_mm(&flat) * UNIT_MARGIN < aperture_mm && extent < aperture_mm {
            self.problems.push(SessionError::Units {
                path: self.path.to_path_buf(),
                entry: "flat_point[0].stage_mm".into(),
                found: format!(
                    "all readings lie within {:.4} mm where the element alone is {:.1} mm across",
                    extent, aperture_mm
                ),
                todo: "m written for mm? multiply by 1000".into(),
            });
        }
    }

    fn counts_and_geometry(&mut self, file: &SessionFile) {
        let std_mm = file.stage_std_um * 1e-3;
        let path = self.path.to_path_buf();
        let pts =
            |v: Vec<[f64; 3]>| -> Vec<Point3<f64>> { v.into_iter().map(Point3::from).collect() };
        let flat = pts(file.flat_point.iter().map(|p| p.stage_mm).collect());
        let element = pts(file.element_point.iter().map(|p| p.stage_mm).collect());
        let targets = pts(file.target_point.iter().map(|p| p.stage_mm).collect());
        let usable = std_mm.is_finite() && std_mm > 0.0;
        let all_finite =
            |p: &[Point3<f64>]| p.iter().all(|q| q.coords.iter().all(|c| c.is_finite()));
        if flat.len() < 3 {
            self.problems.push(SessionError::TooFew {
                path: path.clone(),
                entry: "flat_point",
                count: flat.len(),
                needed: "at least 3, not on one line",
                todo: "focus the PSM on the reference flat at 3 or more places spread over it",
            });
        } else if usable && all_finite(&flat) {
            self.not_on_a_line(
                "flat_point",
                &flat,
                std_mm,
                "add a point away from their line",
            );
        }
        if (1..3).contains(&element.len()) {
            self.problems.push(SessionError::TooFew {
                path: path.clone(),
                entry: "element_point",
                count: element.len(),
                needed: "none, or at least 3 not on one line",
                todo: "add points on the element's front, or remove them all to take it as standing on the reference plane",
            });
        } else if element.len() >= 3 && usable && all_finite(&element) {
            self.not_on_a_line(
                "element_point",
                &element,
                std_mm,
                "add a point away from their line",
            );
        }
        if targets.len() < 6 {
            self.problems.push(SessionError::TooFew {
                path,
                entry: "target_point",
                count: targets.len(),
                needed: "at least 6, not all in one plane",
                todo: "visit the positions `mfd calibrate targets` lists, at two or more heights",
            });
        } else if usable && all_finite(&targets) {
            let s = Spread::of(&targets);
            if s.in_one_plane(std_mm) {
                self.problems.push(SessionError::Coplanar {
                    path: self.path.to_path_buf(),
                    entry: "target_point",
                    count: s.count,
                    off_plane_um: s.off_plane_rms() * 1e3,
                    stage_std_um: std_mm * 1e3,
                    todo: "visit targets at two or more heights (stage z), as `mfd calibrate targets` lists them",
                });
            }
        }
    }

    fn not_on_a_line(
        &mut self,
        entry: &'static str,
        pts: &[Point3<f64>],
        std_mm: f64,
        todo: &'static str,
    ) {
        let s = Spread::of(pts);
        if s.on_one_line(std_mm) {
            self.problems.push(SessionError::Collinear {
                path: self.path.to_path_buf(),
                entry,
                count: s.count,
                off_line_um: s.off_line_rms() * 1e3,
                stage_std_um: std_mm * 1e3,
                todo,
            });
        }
    }
}

/// Every stage reading with its entry name.
fn readings(file: &SessionFile) -> Vec<(String, [f64; 3])> {
    let mut out = Vec::new();
    for (k, p) in file.flat_point.iter().enumerate() {
        out.push((format!("flat_point[{k}].stage_mm"), p.stage_mm));
    }
    for (k, p) in file.element_point.iter().enumerate() {
        out.push((format!("element_point[{k}].stage_mm"), p.stage_mm));
    }
    for (k, p) in file.target_point.iter().enumerate() {
        out.push((format!("target_point[{k}].stage_mm"), p.stage_mm));
    }
    for (k, p) in file.screen_point.iter().enumerate() {
        out.push((format!("screen_point[{k}].stage_mm"), p.stage_mm));
    }
    out
}

/// The largest distance between the camera, the screen's corners and the
/// element's centre, mm: no stage reading of a session can span more.
pub fn station_size_mm(station: &Station) -> f64 {
    let s = &station.screen;
    let (w, h) = (f64::from(s.width), f64::from(s.height));
    let e = station.element.aperture_center_mm;
    let pts = [
        station.camera.position_mm,
        s.world_point(0.0, 0.0),
        s.world_point(w, 0.0),
        s.world_point(0.0, h),
        s.world_point(w, h),
        Point3::new(e.x, e.y, 0.0),
    ];
    extent_mm(&pts)
}

/// The largest distance between two of `pts`.
fn extent_mm(pts: &[Point3<f64>]) -> f64 {
    let mut d: f64 = 0.0;
    for (k, a) in pts.iter().enumerate() {
        for b in &pts[k + 1..] {
            d = d.max((a - b).norm());
        }
    }
    d
}

/// The coordinate-wise median.
fn median_point(pts: &[Point3<f64>]) -> Point3<f64> {
    let median = |k: usize| {
        let mut v: Vec<f64> = pts.iter().map(|p| p[k]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    Point3::new(median(0), median(1), median(2))
}
