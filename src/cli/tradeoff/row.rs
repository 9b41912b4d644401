//! One row of the tradeoff table: a schedule's outcome (errors, reported
//! σ, times, the planner's prediction), and the rows of several noise
//! seeds combined into one.

/// One grid point's outcome.
pub(super) struct Row {
    pub(super) frames: usize,
    pub(super) terms: usize,
    pub(super) max_iter: usize,
    pub(super) found: [f64; 2],
    pub(super) error_nm: [f64; 2],
    pub(super) reported_nm: [f64; 2],
    pub(super) spectral_s: f64,
    pub(super) surfaces_s: f64,
    pub(super) note: String,
    /// Acquisition time at the planner's default timing, s.
    pub(super) acquisition_s: f64,
    /// The planner's predicted bound, nm (NaN where not measured).
    pub(super) predicted_nm: [f64; 2],
    /// A designed schedule (not the uniform family).
    pub(super) designed: bool,
    /// The planner's verdict: the spectral stage measures this schedule.
    pub(super) measurable: bool,
}

/// The rows of one schedule over several noise seeds as one: errors and
/// reported σ as the RMS over the seeds (NaN when any seed measured
/// nothing), points found and times as means, the notes of seeds that
/// had one.
pub(super) fn combine(rows: &[Row]) -> Row {
    let n = rows.len() as f64;
    let rms = |f: &dyn Fn(&Row) -> f64| (rows.iter().map(|r| f(r).powi(2)).sum::<f64>() / n).sqrt();
    let mean = |f: &dyn Fn(&Row) -> f64| rows.iter().map(f).sum::<f64>() / n;
    let mut notes: Vec<&str> = rows
        .iter()
        .map(|r| r.note.as_str())
        .filter(|s| !s.is_empty())
        .collect();
    notes.dedup();
    Row {
        frames: rows[0].frames,
        terms: rows[0].terms,
        max_iter: rows[0].max_iter,
        found: [mean(&|r| r.found[0]), mean(&|r| r.found[1])],
        error_nm: [rms(&|r| r.error_nm[0]), rms(&|r| r.error_nm[1])],
        reported_nm: [rms(&|r| r.reported_nm[0]), rms(&|r| r.reported_nm[1])],
        spectral_s: mean(&|r| r.spectral_s),
        surfaces_s: mean(&|r| r.surfaces_s),
        note: notes.join("; "),
        acquisition_s: f64::NAN,
        predicted_nm: [f64::NAN; 2],
        designed: false,
        measurable: false,
    }
}

/// `a` and `b` as one note.
pub(super) fn join_note(a: &str, b: &str) -> String {
    if a.is_empty() {
        b.to_string()
    } else {
        format!("{a}; {b}")
    }
}
