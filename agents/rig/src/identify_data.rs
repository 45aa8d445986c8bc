//! Measured data in, SI out: CSV files with a column map and units, or MCAP recordings of
//! the rig. Missing values and out-of-order time are dropped and counted, never guessed.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use rig_model::identify::Run;
use rig_model::identify::signals::{GAP_STEPS, median_step};
use rig_protocol::{JointEstimate, JointSample, JointStatus, Topic, decode, decode_samples};
use serde::Serialize;

use crate::error::CliError;

/// Units of a quantity with their factors to SI; the first is the default.
type Units = &'static [(&'static str, f64)];

/// The quantities `rig identify` reads: name, meaning, units.
const QUANTITIES: [(&str, &str, Units); 5] = [
    (
        "t",
        "time",
        &[("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9)],
    ),
    (
        "phi",
        "deflection",
        &[
            ("rad", 1.0),
            ("deg", std::f64::consts::PI / 180.0),
            ("mrad", 1e-3),
        ],
    ),
    (
        "tau",
        "torque",
        &[("Nm", 1.0), ("Nmm", 1e-3), ("mNm", 1e-3)],
    ),
    ("d", "pivot position", &[("mm", 1e-3), ("m", 1.0)]),
    (
        "q",
        "link angle",
        &[
            ("rad", 1.0),
            ("deg", std::f64::consts::PI / 180.0),
            ("mrad", 1e-3),
        ],
    ),
];

/// The measured data a command fits and scores on (flattened into `rig identify` and
/// `rig calibrate`).
#[derive(Debug, clap::Args)]
pub struct DataArgs {
    /// Measured data to fit: CSV (a header row naming the columns; `,` `;` tab or space
    /// separated, decimal commas, `#` comments and a `# t,phi,tau` header as numpy's savetxt
    /// writes are read too) or an MCAP recording of the rig. Repeatable
    #[arg(long, required = true, value_name = "FILE")]
    pub data: Vec<std::path::PathBuf>,
    /// Data held out of the fit, on which the before/after figures are computed. Repeatable.
    /// Without it, `rig identify` holds out every fourth time block of each --data file and
    /// `rig calibrate` scores on the fit data
    #[arg(long, value_name = "FILE")]
    pub holdout: Vec<std::path::PathBuf>,
    /// Which CSV column is which quantity, with units: QUANTITY=COLUMN[:UNIT],…
    /// Quantities: t (s|ms|us|ns), phi (rad|deg|mrad), tau (Nm|Nmm|mNm), d (mm|m), q (rad|deg|mrad).
    /// Default: columns named t, phi, tau, d, q in s, rad, N·m, mm, rad
    #[arg(long, value_name = "MAP", verbatim_doc_comment)]
    pub columns: Option<String>,
}

/// Where each quantity comes from: a column name and the factor to SI.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnMap {
    pub columns: BTreeMap<&'static str, (String, f64, &'static str)>,
    /// Quantities named explicitly (a missing column is then an error, not "absent").
    pub explicit: Vec<&'static str>,
}

impl ColumnMap {
    /// Parses `t=time,phi=displacement:deg,tau=torque_out`. Unnamed quantities keep their
    /// default column (their own name) and unit (s, rad, N·m, mm for d, rad).
    pub fn parse(spec: Option<&str>) -> Result<Self, CliError> {
        let mut columns = BTreeMap::new();
        for (q, _, units) in QUANTITIES {
            columns.insert(q, (q.to_string(), units[0].1, units[0].0));
        }
        let mut explicit = Vec::new();
        let bad = |m: String| CliError::Invalid(format!("--columns: {m}"));
        for item in spec
            .unwrap_or("")
            .split(',')
            .filter(|s| !s.trim().is_empty())
        {
            let (q, rest) = item
                .split_once('=')
                .ok_or_else(|| bad(format!("\"{item}\" is not QUANTITY=COLUMN[:UNIT]")))?;
            let q = q.trim();
            let Some((name, _, units)) = QUANTITIES.iter().find(|(n, _, _)| *n == q) else {
                return Err(bad(format!(
                    "unknown quantity \"{q}\"; known: t, phi, tau, d, q"
                )));
            };
            let (col, unit) = match rest.split_once(':') {
                Some((c, u)) => (c.trim(), Some(u.trim())),
                None => (rest.trim(), None),
            };
            if col.is_empty() {
                return Err(bad(format!("{q}: no column name")));
            }
            let (u, f) = match unit {
                None => (units[0].0, units[0].1),
                Some(u) => match units.iter().find(|(n, _)| *n == u) {
                    Some((n, f)) => (*n, *f),
                    None => {
                        let ok: Vec<&str> = units.iter().map(|(n, _)| *n).collect();
                        return Err(bad(format!(
                            "{q}: unit \"{u}\" is not one of {}",
                            ok.join(", ")
                        )));
                    }
                },
            };
            columns.insert(*name, (col.to_string(), f, u));
            explicit.push(*name);
        }
        Ok(Self { columns, explicit })
    }
}

/// What reading a file found.
#[derive(Debug, Clone, Serialize)]
pub struct Sampling {
    pub file: String,
    pub rows: usize,
    pub used: usize,
    /// Rows dropped for a missing or unreadable value, per quantity.
    pub missing: BTreeMap<String, usize>,
    /// Rows dropped because time did not increase.
    pub time_not_increasing: usize,
    pub dt_median_s: f64,
    pub dt_p99_s: f64,
    pub dt_max_s: f64,
    /// Steps longer than [`GAP_STEPS`] median steps: gaps in the recording.
    pub gaps: usize,
    /// Sampling rate varies: p99 step over 1.5 median steps.
    pub irregular: bool,
    /// The columns read, with their units.
    pub columns: BTreeMap<String, String>,
    /// How a CSV file was laid out (none for a recording).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub layout: Option<Layout>,
}

fn sampling(file: &str, rows: usize, t: &[f64]) -> Sampling {
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let med = median_step(t);
    let p99 = steps.get(steps.len() * 99 / 100).copied().unwrap_or(0.0);
    Sampling {
        file: file.to_string(),
        rows,
        used: t.len(),
        missing: BTreeMap::new(),
        time_not_increasing: 0,
        dt_median_s: med,
        dt_p99_s: p99,
        dt_max_s: steps.last().copied().unwrap_or(0.0),
        gaps: steps.iter().filter(|s| **s > GAP_STEPS * med).count(),
        irregular: p99 > 1.5 * med,
        columns: BTreeMap::new(),
        layout: None,
    }
}

/// Reads a CSV or MCAP file into a run.
pub fn read(
    path: &Path,
    map: &ColumnMap,
    joint: Option<&str>,
) -> Result<(Run, Sampling), CliError> {
    let is_mcap = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
    if is_mcap {
        read_mcap(path, joint)
    } else {
        read_csv(path, map)
    }
}

/// How a CSV file is laid out, read from its first lines: what a lab's logger, a spreadsheet
/// or a script writes, not only `,` and a plain header row.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Layout {
    /// The field separator: `,`, `;`, a tab, or runs of spaces (`" "`, numpy's `savetxt`).
    pub separator: String,
    /// Numbers written with a decimal comma (`1,5`; a `;`- or tab-separated spreadsheet export).
    pub decimal_comma: bool,
    /// The header row was a `#` comment (numpy's `savetxt(…, header=…)` writes `# t,phi,tau`).
    pub header_commented: bool,
    /// `#` comment lines skipped (metadata before or inside the data).
    pub comment_lines: usize,
    /// The header row is all numbers: perhaps a data row, the header missing.
    #[serde(skip)]
    pub header_is_numbers: bool,
}

impl Layout {
    /// What was read other than a plain comma-separated file with a header row: `None` for
    /// that, else e.g. "`;`-separated, decimal commas, the header from a # comment".
    pub fn note(&self) -> Option<String> {
        let mut parts = Vec::new();
        if self.separator != "," {
            parts.push(format!(
                "{}-separated",
                if self.separator.len() == 1 {
                    format!("`{}`", self.separator)
                } else {
                    self.separator.clone()
                }
            ));
        }
        if self.decimal_comma {
            parts.push("decimal commas".to_string());
        }
        if self.header_commented {
            parts.push("the header from a # comment".to_string());
        }
        if self.comment_lines > 0 {
            parts.push(format!("{} # comment lines skipped", self.comment_lines));
        }
        (!parts.is_empty()).then(|| parts.join(", "))
    }
}

/// A layout's separator.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Separator {
    Byte(u8),
    Spaces,
}

impl Separator {
    /// The one the line uses: the most frequent of `,` `;` tab, else runs of spaces.
    fn of(line: &str) -> Self {
        [b',', b';', b'\t']
            .into_iter()
            .map(|b| (line.bytes().filter(|c| *c == b).count(), b))
            .filter(|(n, _)| *n > 0)
            .max_by_key(|(n, _)| *n)
            .map_or(Self::Spaces, |(_, b)| Self::Byte(b))
    }

    fn split<'a>(&self, line: &'a str) -> Vec<&'a str> {
        match self {
            Self::Byte(b) => line.split(char::from(*b)).map(str::trim).collect(),
            Self::Spaces => line.split_whitespace().collect(),
        }
    }

    fn name(&self) -> String {
        match self {
            Self::Byte(b'\t') => "tab".into(),
            Self::Byte(b) => char::from(*b).to_string(),
            Self::Spaces => "spaces".into(),
        }
    }
}

/// Whether every field of a line reads as a number (a data row, not a header).
fn all_numbers(fields: &[&str], decimal_comma: bool) -> bool {
    !fields.is_empty()
        && fields.iter().all(|f| {
            let f = f.trim_matches('"');
            let f = if decimal_comma {
                std::borrow::Cow::Owned(f.replace(',', "."))
            } else {
                std::borrow::Cow::Borrowed(f)
            };
            f.parse::<f64>().is_ok()
        })
}

/// Reads a CSV text's layout and rewrites it as plain comma-separated text with its header
/// row first: a UTF-8 byte-order mark dropped; `#` lines skipped as comments, except that where
/// the first other line is already numbers the last comment before it is the header (numpy's
/// `savetxt`); the separator the header uses (`,` `;` tab, else spaces); a decimal comma where
/// the separator is not a comma and the first data row has one. Errors name what is missing.
fn normalise(text: &str) -> Result<(String, Layout), String> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let is_comment = |l: &str| l.trim_start().starts_with('#');
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let mut comments: Vec<&str> = Vec::new();
    let first = loop {
        match lines.next() {
            Some(l) if is_comment(l) => comments.push(l),
            Some(l) => break l,
            None => {
                return Err("no header row and no data (an empty file, or only # comments)".into());
            }
        }
    };
    let sep = Separator::of(first);
    let mut rest: Vec<&str> = lines.collect();
    let data_first = all_numbers(&sep.split(first), false) || all_numbers(&sep.split(first), true);
    // A first line of numbers after a comment: the comment is the header. Without one it
    // stays the header (columns named 0, 1, 2 are a header too); if no column is found there,
    // the error says the header row may be missing.
    let (header, header_commented) = match comments.pop() {
        Some(h) if data_first => {
            rest.insert(0, first);
            (h.trim_start().trim_start_matches('#').trim(), true)
        }
        Some(h) => {
            comments.push(h);
            (first, false)
        }
        None => (first, false),
    };
    let sep = if header_commented {
        Separator::of(header)
    } else {
        sep
    };
    let mut comment_lines = comments.len();
    rest.retain(|l| {
        let c = is_comment(l);
        comment_lines += usize::from(c);
        !c
    });
    let decimal_comma = sep != Separator::Byte(b',')
        && rest.first().is_some_and(|l| {
            l.contains(',')
                && !all_numbers(&sep.split(l), false)
                && all_numbers(&sep.split(l), true)
        });
    let mut out = String::with_capacity(text.len() + 16);
    let mut push = |line: &str, decimal: bool| {
        let fields = sep.split(line);
        for (i, f) in fields.iter().enumerate() {
            if i > 0 {
                out.push(',');
            }
            let f = if decimal {
                f.replace(',', ".")
            } else {
                (*f).to_string()
            };
            if f.contains(',') || f.contains('"') {
                out.push('"');
                out.push_str(&f.replace('"', "\"\""));
                out.push('"');
            } else {
                out.push_str(&f);
            }
        }
        out.push('\n');
    };
    match sep {
        // A comma-separated file goes to the csv reader as it is (quoted fields and all).
        Separator::Byte(b',') => {
            out.push_str(header);
            out.push('\n');
            for l in &rest {
                out.push_str(l);
                out.push('\n');
            }
        }
        _ => {
            push(header, false);
            for l in &rest {
                push(l, decimal_comma);
            }
        }
    }
    Ok((
        out,
        Layout {
            separator: sep.name(),
            decimal_comma,
            header_commented,
            comment_lines,
            header_is_numbers: data_first && !header_commented,
        },
    ))
}

/// The column a header names `col`: the same name, else the one name that differs only in case.
fn column_of(headers: &[String], col: &str) -> Option<usize> {
    headers.iter().position(|h| h == col).or_else(|| {
        let mut same = headers
            .iter()
            .enumerate()
            .filter(|(_, h)| h.eq_ignore_ascii_case(col));
        match (same.next(), same.next()) {
            (Some((i, _)), None) => Some(i),
            _ => None,
        }
    })
}

fn read_csv(path: &Path, map: &ColumnMap) -> Result<(Run, Sampling), CliError> {
    let name = path.display().to_string();
    let bad = |m: String| CliError::Invalid(format!("{name}: {m}"));
    let csv_err = |source| CliError::Csv {
        file: name.clone(),
        source,
    };
    let bytes = std::fs::read(path).map_err(|e| bad(format!("cannot read it: {e}")))?;
    let (text, layout) = normalise(&String::from_utf8_lossy(&bytes)).map_err(bad)?;
    let mut rdr = csv::ReaderBuilder::new()
        .flexible(true)
        .from_reader(text.as_bytes());
    let headers: Vec<String> = rdr
        .headers()
        .map_err(csv_err)?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    // Which quantities are present, and where.
    let mut idx: BTreeMap<&'static str, (usize, f64)> = BTreeMap::new();
    let mut cols_used = BTreeMap::new();
    for (q, (col, f, unit)) in &map.columns {
        match column_of(&headers, col) {
            Some(i) => {
                idx.insert(q, (i, *f));
                cols_used.insert(q.to_string(), format!("{col} [{unit}]"));
            }
            None if map.explicit.contains(q) || ["t", "tau"].contains(q) => {
                return Err(bad(format!(
                    "no column \"{col}\" for {q}; the header has: {}{}{}",
                    headers.join(", "),
                    if layout.header_is_numbers {
                        " (all numbers: is the header row missing? The first line must name the columns)"
                    } else {
                        ""
                    },
                    if map.explicit.is_empty() {
                        " (map columns with --columns, e.g. t=time,phi=displacement:deg,tau=torque_out)"
                    } else {
                        ""
                    }
                )));
            }
            None => {}
        }
    }
    let mut cols: BTreeMap<&'static str, Vec<f64>> = idx.keys().map(|q| (*q, Vec::new())).collect();
    let mut missing: BTreeMap<String, usize> = BTreeMap::new();
    let (mut rows, mut back) = (0usize, 0usize);
    let mut last_t = f64::NEG_INFINITY;
    for rec in rdr.records() {
        let rec = rec.map_err(csv_err)?;
        rows += 1;
        let mut vals = Vec::with_capacity(idx.len());
        let mut ok = true;
        for (q, (i, f)) in &idx {
            let v = rec
                .get(*i)
                .and_then(|s| s.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite());
            match v {
                Some(v) => vals.push((*q, v * f)),
                None => {
                    *missing.entry(q.to_string()).or_default() += 1;
                    ok = false;
                }
            }
        }
        if !ok {
            continue;
        }
        let t = vals
            .iter()
            .find(|(q, _)| *q == "t")
            .map_or(f64::NAN, |v| v.1);
        if t <= last_t {
            back += 1;
            continue;
        }
        last_t = t;
        for (q, v) in vals {
            if let Some(c) = cols.get_mut(q) {
                c.push(v);
            }
        }
    }
    let mut take = |q: &str| cols.remove(q);
    let run = Run {
        name: file_name(path),
        t: take("t").unwrap_or_default(),
        tau: take("tau").unwrap_or_default(),
        phi: take("phi"),
        d: take("d"),
        q: take("q"),
    };
    if run.t.len() < 20 {
        return Err(bad(format!(
            "{} usable rows of {rows}; at least 20 are needed",
            run.t.len()
        )));
    }
    let mut s = sampling(&name, rows, &run.t);
    s.missing = missing;
    s.time_not_increasing = back;
    s.columns = cols_used;
    s.layout = Some(layout);
    Ok((run, s))
}

/// One joint of an MCAP recording: its acquisition-stamped samples with a torque sensor.
fn read_mcap(path: &Path, joint: Option<&str>) -> Result<(Run, Sampling), CliError> {
    let name = path.display().to_string();
    let bad = |m: String| CliError::Invalid(format!("{name}: {m}"));
    let (msgs, _) = crate::record::read_all(path)?;
    // A board of several joints sends its ticks on its board key (kind 9), each sample naming
    // its joint by index: the names come from the joints' own keys (statuses, estimates).
    // One message per joint key is enough: a joint already named is not decoded again.
    let mut name_of: BTreeMap<u16, String> = BTreeMap::new();
    let mut named: BTreeSet<String> = BTreeSet::new();
    for m in &msgs {
        let index = match Topic::parse(&m.topic) {
            Ok(Topic::JointStatus { joint, .. }) if !named.contains(&joint) => {
                decode::<JointStatus>(&m.data)
                    .ok()
                    .map(|s| (s.joint, joint))
            }
            Ok(Topic::JointEstimate { joint, .. }) if !named.contains(&joint) => {
                decode::<JointEstimate>(&m.data)
                    .ok()
                    .map(|e| (e.joint, joint))
            }
            _ => None,
        };
        if let Some((i, name)) = index {
            named.insert(name.clone());
            name_of.entry(i).or_insert(name);
        }
    }
    let mut by_joint: BTreeMap<String, Vec<JointSample>> = BTreeMap::new();
    for m in &msgs {
        let on_key = match Topic::parse(&m.topic) {
            Ok(Topic::JointSample { joint, .. }) => Some(joint),
            Ok(Topic::BoardSample { .. }) => None,
            _ => continue,
        };
        for s in decode_samples(&m.data).unwrap_or_default() {
            let j = on_key.clone().unwrap_or_else(|| {
                name_of
                    .get(&s.joint)
                    .cloned()
                    .unwrap_or_else(|| format!("#{}", s.joint))
            });
            by_joint.entry(j).or_default().push(s);
        }
    }
    let names: Vec<String> = by_joint.keys().cloned().collect();
    if names.is_empty() {
        return Err(bad(
            "holds no joint samples (was it recorded with the rig's --config? `rig record` listens on rig/<name>/**)".into(),
        ));
    }
    let j = match joint {
        Some(j) => j.to_string(),
        None => names
            .first()
            .cloned()
            .ok_or_else(|| bad("holds no joint samples".into()))?,
    };
    let mut samples = by_joint.remove(&j).ok_or_else(|| {
        bad(format!(
            "holds no samples of joint \"{j}\"; it has: {}",
            names.join(", ")
        ))
    })?;
    samples.sort_by_key(|s| s.t_acq_ns);
    let rows = samples.len();
    let t0 = samples.first().map_or(0, |s| s.t_acq_ns);
    let (mut t, mut tau, mut phi, mut d, mut q) = (vec![], vec![], vec![], vec![], vec![]);
    let mut no_torque = 0;
    let mut last = None;
    let mut back = 0;
    for s in &samples {
        let Some(tq) = s.torque_nm else {
            no_torque += 1;
            continue;
        };
        if last.is_some_and(|l| s.t_acq_ns <= l) {
            back += 1;
            continue;
        }
        last = Some(s.t_acq_ns);
        t.push((s.t_acq_ns - t0) as f64 * 1e-9);
        tau.push(tq);
        phi.push(s.deflection_rad);
        d.push(s.pivot_m.unwrap_or(0.0));
        q.push(s.motor_rad + s.deflection_rad);
    }
    if t.len() < 20 {
        return Err(bad(format!(
            "joint \"{j}\": {} samples carry a torque-sensor reading (of {rows}); identification needs the sensor",
            t.len()
        )));
    }
    let mut smp = sampling(&format!("{name} (joint {j})"), rows, &t);
    if no_torque > 0 {
        smp.missing.insert("tau".into(), no_torque);
    }
    smp.time_not_increasing = back;
    smp.columns = [
        ("t", "t_acq_ns [ns]"),
        ("phi", "deflection_rad [rad]"),
        ("tau", "torque_nm [Nm]"),
        ("d", "pivot_m [m]"),
        ("q", "motor_rad + deflection_rad [rad]"),
    ]
    .into_iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect();
    Ok((
        Run {
            name: format!("{} ({j})", file_name(path)),
            t,
            tau,
            phi: Some(phi),
            d: Some(d),
            q: Some(q),
        },
        smp,
    ))
}

fn file_name(p: &Path) -> String {
    p.file_name().map_or_else(
        || p.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn column_maps_convert_units_and_name_bad_parts() {
        let m = ColumnMap::parse(Some("t=time,phi=displacement:deg,tau=torque_out:Nmm")).unwrap();
        assert_eq!(m.columns["phi"].0, "displacement");
        assert!((m.columns["phi"].1 - std::f64::consts::PI / 180.0).abs() < 1e-15);
        assert_eq!(m.columns["tau"].1, 1e-3);
        assert_eq!(m.columns["d"].1, 1e-3, "d defaults to mm");
        let m = ColumnMap::parse(Some("t=stamp:ns,phi=x:mrad,tau=y:mNm,q=z:mrad")).unwrap();
        assert_eq!(m.columns["t"].1, 1e-9);
        assert_eq!(m.columns["phi"].1, 1e-3);
        assert_eq!(m.columns["tau"].1, 1e-3);
        assert_eq!(m.columns["q"].1, 1e-3);
        let e = ColumnMap::parse(Some("phi=x:furlong"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("furlong") && e.contains("rad, deg"), "{e}");
        let e = ColumnMap::parse(Some("theta=x")).unwrap_err().to_string();
        assert!(e.contains("theta"), "{e}");
    }

    #[test]
    fn csv_rows_with_missing_values_or_time_going_back_are_dropped_and_counted() {
        let dir = std::env::temp_dir().join(format!("rig-idata-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("a.csv");
        let mut s = String::from(",time,displacement,torque_out\n");
        for i in 0..40 {
            let t = i as f64 * 0.01;
            match i {
                5 => s.push_str(&format!("{i},{t},,1.0\n")),
                6 => s.push_str(&format!("{i},{t},nan,1.0\n")),
                7 => s.push_str(&format!("{i},0.0,1.0,1.0\n")),
                _ => s.push_str(&format!("{i},{t},{},{}\n", i as f64, 2.0 * i as f64)),
            }
        }
        std::fs::write(&f, s).unwrap();
        let m = ColumnMap::parse(Some("t=time,phi=displacement:deg,tau=torque_out")).unwrap();
        let (run, smp) = read(&f, &m, None).unwrap();
        assert_eq!(smp.rows, 40);
        assert_eq!(smp.used, 37);
        assert_eq!(smp.missing["phi"], 2);
        assert_eq!(smp.time_not_increasing, 1);
        assert!((run.phi.unwrap()[1] - 1f64.to_radians()).abs() < 1e-15);
        assert_eq!(smp.gaps, 0);
        let e = read(&f, &ColumnMap::parse(None).unwrap(), None)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no column \"t\"") && e.contains("--columns"),
            "{e}"
        );
    }

    /// The 40 rows (t, φ, τ) every layout of the test below writes.
    fn rows() -> Vec<[f64; 3]> {
        (0..40)
            .map(|i| {
                let t = 0.001 * f64::from(i);
                [t, 0.01 * (7.0 * t).sin(), 2.5 * (7.0 * t).sin() - 0.125]
            })
            .collect()
    }

    #[test]
    fn csv_files_as_loggers_spreadsheets_and_numpy_write_them_are_read_alike() {
        let dir = std::env::temp_dir().join(format!("rig-layouts-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let line = |r: &[f64; 3], sep: &str, decimal_comma: bool| {
            r.iter()
                .map(|v| {
                    let v = format!("{v:e}");
                    if decimal_comma {
                        v.replace('.', ",")
                    } else {
                        v
                    }
                })
                .collect::<Vec<_>>()
                .join(sep)
        };
        let body = |sep: &str, dc: bool, eol: &str| -> String {
            rows().iter().map(|r| line(r, sep, dc) + eol).collect()
        };
        // (file, text, what the layout note says)
        let cases: Vec<(&str, String, Option<&str>)> = vec![
            (
                "plain.csv",
                format!("t,phi,tau\n{}", body(",", false, "\n")),
                None,
            ),
            (
                "excel.csv",
                format!("\u{feff}t;phi;tau\r\n{}", body(";", true, "\r\n")),
                Some("`;`-separated, decimal commas"),
            ),
            (
                "savetxt.txt",
                format!("# t phi tau\n{}", body(" ", false, "\n")),
                Some("spaces-separated, the header from a # comment"),
            ),
            (
                "savetxt.csv",
                format!("# t,phi,tau\n{}", body(",", false, "\n")),
                Some("the header from a # comment"),
            ),
            (
                "logger.tsv",
                format!(
                    "# bench logger 1.2\n# 1 kHz\n\nT\tPhi\tTAU\n{}# paused\n{}",
                    body("\t", false, "\n"),
                    ""
                ),
                Some("tab-separated, 3 # comment lines skipped"),
            ),
        ];
        let map = ColumnMap::parse(None).unwrap();
        let want = rows();
        for (file, text, note) in cases {
            let f = dir.join(file);
            std::fs::write(&f, text).unwrap();
            let (run, smp) = read(&f, &map, None).unwrap_or_else(|e| panic!("{file}: {e}"));
            assert_eq!(smp.used, 40, "{file}");
            let phi = run.phi.as_ref().unwrap();
            for (i, r) in want.iter().enumerate() {
                assert_eq!([run.t[i], phi[i], run.tau[i]], *r, "{file} row {i}");
            }
            assert_eq!(
                smp.layout.as_ref().unwrap().note().as_deref(),
                note,
                "{file}"
            );
        }
    }

    #[test]
    fn a_file_with_no_header_or_no_rows_is_refused_saying_so() {
        let dir = std::env::temp_dir().join(format!("rig-noheader-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let map = ColumnMap::parse(None).unwrap();
        let err = |name: &str, text: &str| {
            let f = dir.join(name);
            std::fs::write(&f, text).unwrap();
            read(&f, &map, None).unwrap_err().to_string()
        };
        let e = err("empty.csv", "");
        assert!(
            e.contains("empty.csv") && e.contains("no header row"),
            "{e}"
        );
        let e = err("comments.csv", "# only\n# comments\n");
        assert!(e.contains("only # comments"), "{e}");
        let e = err("numbers.csv", "0.0,0.1,0.2\n0.001,0.1,0.2\n");
        assert!(
            e.contains("no column \"t\"") && e.contains("is the header row missing"),
            "{e}"
        );
        // Two columns that differ from `tau` only in case: which one is meant is not guessed.
        let mut text = String::from("t,phi,Tau,TAU\n");
        for i in 0..30 {
            text.push_str(&format!("{},0.0,1.0,2.0\n", f64::from(i) * 0.01));
        }
        let e = err("twice.csv", &text);
        assert!(e.contains("no column \"tau\""), "{e}");
    }
}
