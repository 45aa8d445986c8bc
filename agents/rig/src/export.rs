//! `rig export run.mcap --to csv DIR`: one CSV file per topic, for pandas and spreadsheets.
//!
//! Each message's JSON (a recording's own, or a rig message decoded from an older
//! `rig-wire/1` channel) is flattened into columns, in the order of its fields: a field keeps
//! its name, which carries its unit (`deflection_rad`, `t_acq_ns`); a nested field is `outer.inner`, a list's items
//! `name.0`, `name.1`, …; an absent optional value is an empty cell. The first column is the
//! recorder's `log_time_ns`. A board's tick (kind 9, on `…/board/<b>/sample`) is one row per
//! joint sample, with the same columns as a joint's own sample topic. A payload that was not a
//! rig message is written as hex in `wire_hex`, so nothing in the recording is lost.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rig_protocol::json::to_json;
use rig_protocol::{Topic, decode_any};
use serde::de::{Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};

use crate::error::CliError;
use crate::record::{JSON, Stored, WIRE, read_stored};

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Format {
    /// One CSV file per topic (`/` in the topic becomes `.`), a header row naming each column
    Csv,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The recording (.mcap), from `rig record` or `rig sim --out`
    file: PathBuf,
    /// What to write
    #[arg(long, value_enum, value_name = "FORMAT")]
    to: Format,
    /// Directory for the files (made if missing; files of the same name are replaced)
    dir: PathBuf,
}

/// One topic's rows: column names in first-seen order, and each row's cells by column.
#[derive(Default)]
struct Table {
    columns: Vec<String>,
    index: BTreeMap<String, usize>,
    rows: Vec<Vec<(usize, String)>>,
}

impl Table {
    fn push(&mut self, cells: Vec<(String, String)>) {
        let row = cells
            .into_iter()
            .map(|(name, value)| {
                let next = self.columns.len();
                let i = *self.index.entry(name.clone()).or_insert(next);
                if i == next {
                    self.columns.push(name);
                }
                (i, value)
            })
            .collect();
        self.rows.push(row);
    }
}

/// A JSON value with its objects' fields in the order they were written (serde_json's own
/// `Value` sorts them by name), each leaf already as its cell's text.
#[derive(Debug)]
enum Node {
    Cell(String),
    Null,
    List(Vec<Node>),
    Object(Vec<(String, Node)>),
}

impl<'de> Deserialize<'de> for Node {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Node;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a JSON value")
            }
            fn visit_bool<E>(self, v: bool) -> Result<Node, E> {
                Ok(Node::Cell(v.to_string()))
            }
            fn visit_i64<E>(self, v: i64) -> Result<Node, E> {
                Ok(Node::Cell(v.to_string()))
            }
            fn visit_u64<E>(self, v: u64) -> Result<Node, E> {
                Ok(Node::Cell(v.to_string()))
            }
            fn visit_f64<E>(self, v: f64) -> Result<Node, E> {
                // The shortest form that reads back to the same number.
                Ok(serde_json::Number::from_f64(v)
                    .map_or(Node::Null, |n| Node::Cell(n.to_string())))
            }
            fn visit_str<E>(self, v: &str) -> Result<Node, E> {
                Ok(Node::Cell(v.to_string()))
            }
            fn visit_unit<E>(self) -> Result<Node, E> {
                Ok(Node::Null)
            }
            fn visit_none<E>(self) -> Result<Node, E> {
                Ok(Node::Null)
            }
            fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Node, D::Error> {
                Node::deserialize(d)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<Node, A::Error> {
                let mut items = Vec::new();
                while let Some(n) = a.next_element()? {
                    items.push(n);
                }
                Ok(Node::List(items))
            }
            fn visit_map<A: MapAccess<'de>>(self, mut a: A) -> Result<Node, A::Error> {
                let mut fields = Vec::new();
                while let Some((k, v)) = a.next_entry::<String, Node>()? {
                    fields.push((k, v));
                }
                Ok(Node::Object(fields))
            }
        }
        d.deserialize_any(V)
    }
}

/// `node`'s leaves as (column, cell): objects by `.`-joined names, lists by index.
fn flatten(prefix: &str, node: &Node, out: &mut Vec<(String, String)>) {
    let name = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match node {
        Node::Object(fields) => {
            for (k, v) in fields {
                flatten(&name(k), v, out);
            }
        }
        Node::List(items) => {
            for (i, v) in items.iter().enumerate() {
                flatten(&name(&i.to_string()), v, out);
            }
        }
        Node::Null => out.push((prefix.to_string(), String::new())),
        Node::Cell(c) => out.push((prefix.to_string(), c.clone())),
    }
}

/// The rows of one stored message: one, or one per joint sample of a board's tick.
fn rows(m: &Stored) -> Result<Vec<Vec<(String, String)>>, String> {
    let time = || ("log_time_ns".to_string(), m.log_time.to_string());
    let json = match m.encoding.as_str() {
        JSON => serde_json::from_slice::<Node>(&m.data).map_err(|e| format!("not JSON: {e}"))?,
        WIRE => match decode_any(&m.data) {
            Ok(msg) => serde_json::from_slice::<Node>(&to_json(&msg)).map_err(|e| e.to_string())?,
            Err(_) => {
                let hex: String = m.data.iter().map(|b| format!("{b:02x}")).collect();
                return Ok(vec![vec![time(), ("wire_hex".to_string(), hex)]]);
            }
        },
        other => {
            return Err(format!(
                "message encoding {other:?} (expected {JSON} or {WIRE})"
            ));
        }
    };
    let row = |node: &Node| {
        let mut out = vec![time()];
        flatten("", node, &mut out);
        out
    };
    let board = matches!(Topic::parse(&m.topic), Ok(Topic::BoardSample { .. }));
    Ok(match (board, &json) {
        (true, Node::Object(fields)) => match fields.as_slice() {
            [(name, Node::List(samples))] if name == "samples" => samples.iter().map(row).collect(),
            _ => vec![row(&json)],
        },
        _ => vec![row(&json)],
    })
}

/// A file name for `topic`: `/` becomes `.`, anything but letters, digits, `.`, `_`, `-`
/// becomes `_`.
fn file_name(topic: &str) -> String {
    let stem: String = topic
        .trim_matches('/')
        .chars()
        .map(|c| match c {
            '/' => '.',
            c if c.is_ascii_alphanumeric() || "._-".contains(c) => c,
            _ => '_',
        })
        .collect();
    format!("{}.csv", if stem.is_empty() { "_" } else { &stem })
}

fn csv_err(file: &Path) -> impl Fn(csv::Error) -> CliError + '_ {
    move |source| CliError::Csv {
        file: file.display().to_string(),
        source,
    }
}

pub fn run(a: &Args) -> Result<(), CliError> {
    let Format::Csv = a.to;
    let (stored, truncated) = read_stored(&a.file)?;
    if truncated {
        eprintln!(
            "rig export: {} ends in a partial record (recorder killed?); exporting its {} complete messages",
            a.file.display(),
            stored.len()
        );
    }
    let mut tables: BTreeMap<&str, Table> = BTreeMap::new();
    for m in &stored {
        let rows = rows(m).map_err(|e| {
            CliError::Invalid(format!(
                "{}: message {} on {}: {e}",
                a.file.display(),
                m.sequence,
                m.topic
            ))
        })?;
        let table = tables.entry(m.topic.as_str()).or_default();
        for row in rows {
            table.push(row);
        }
    }
    std::fs::create_dir_all(&a.dir)?;
    let mut names: BTreeMap<String, &str> = BTreeMap::new();
    for (topic, t) in &tables {
        let name = file_name(topic);
        if let Some(other) = names.insert(name.clone(), topic) {
            return Err(CliError::Invalid(format!(
                "topics {other:?} and {topic:?} would both be written to {name}"
            )));
        }
        let path = a.dir.join(&name);
        let mut w = csv::Writer::from_path(&path).map_err(csv_err(&path))?;
        w.write_record(&t.columns).map_err(csv_err(&path))?;
        let mut line = vec![String::new(); t.columns.len()];
        for row in &t.rows {
            line.iter_mut().for_each(String::clear);
            for (i, v) in row {
                line[*i].clone_from(v);
            }
            w.write_record(&line).map_err(csv_err(&path))?;
        }
        w.flush()?;
        eprintln!(
            "{}: {} rows × {} columns",
            path.display(),
            t.rows.len(),
            t.columns.len()
        );
    }
    eprintln!(
        "rig export: {} messages on {} topics from {} into {}",
        stored.len(),
        tables.len(),
        a.file.display(),
        a.dir.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_fields_and_lists_become_dotted_columns_and_null_an_empty_cell() {
        let v: Node = serde_json::from_str(
            r#"{"t_ns": 5, "force_n": [1.5, -2e-7], "pivot_m": null, "s": {"a_rad": 0.1, "ok": true}}"#,
        )
        .unwrap();
        let mut out = Vec::new();
        flatten("", &v, &mut out);
        // In the order written, numbers in their shortest exact form.
        let want = [
            ("t_ns", "5"),
            ("force_n.0", "1.5"),
            ("force_n.1", "-2e-7"),
            ("pivot_m", ""),
            ("s.a_rad", "0.1"),
            ("s.ok", "true"),
        ];
        let got: Vec<(&str, &str)> = out.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect();
        assert_eq!(got, want);
    }

    #[test]
    fn a_column_first_seen_late_is_appended_and_earlier_rows_leave_it_empty() {
        let mut t = Table::default();
        t.push(vec![("a".into(), "1".into())]);
        t.push(vec![("b".into(), "2".into()), ("a".into(), "3".into())]);
        assert_eq!(t.columns, ["a", "b"]);
        assert_eq!(t.rows[1], [(1, "2".to_string()), (0, "3".to_string())]);
    }

    #[test]
    fn a_boards_tick_is_one_row_per_joint_sample_with_a_joint_samples_columns() {
        let sample = rig_protocol::JointSample {
            joint: 1,
            seq: 3,
            t_acq_ns: 1_700_000_000_000_000_000,
            motor_rad: 0.5,
            deflection_rad: -0.01,
            pivot_m: Some(0.009),
            torque_nm: None,
            motor_torque_nm: None,
            stiffness_motor_rad: None,
        };
        let other = rig_protocol::JointSample {
            joint: 2,
            torque_nm: Some(0.25),
            ..sample
        };
        let board = rig_protocol::BoardSample {
            samples: vec![sample, other],
        };
        let stored = |topic: &str, msg: rig_protocol::AnyMessage| Stored {
            topic: topic.into(),
            encoding: JSON.into(),
            schema: String::new(),
            sequence: 0,
            log_time: 42,
            data: to_json(&msg),
        };
        let one = rows(&stored("rig/r/joint/j1/sample", sample.into())).unwrap();
        let tick = rows(&stored("rig/r/board/b/sample", board.into())).unwrap();
        assert_eq!(tick.len(), 2);
        assert_eq!(tick[0], one[0]);
        let columns = |r: &[(String, String)]| r.iter().map(|c| c.0.clone()).collect::<Vec<_>>();
        assert_eq!(columns(&tick[1]), columns(&one[0]));
        assert!(tick[1].contains(&("torque_nm".into(), "0.25".into())));
        assert!(tick[1].contains(&("log_time_ns".into(), "42".into())));
    }

    #[test]
    fn topics_become_file_names_without_separators() {
        assert_eq!(
            file_name("rig/bench/joint/j1/sample"),
            "rig.bench.joint.j1.sample.csv"
        );
        assert_eq!(file_name("sim/a b*"), "sim.a_b_.csv");
    }
}
