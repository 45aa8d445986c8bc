//! Errors that name the file, the line and the field, and say what is allowed.

use std::fmt;
use std::path::{Path, PathBuf};

use toml::de::DeTable;

/// One segment of a field path: a key or an array index.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Seg {
    Key(&'static str),
    Index(usize),
}

/// A field path such as `joint[2].lever.p_mm`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct FieldPath(pub Vec<Seg>);

impl FieldPath {
    /// This path extended by a key.
    pub fn key(&self, k: &'static str) -> Self {
        let mut v = self.0.clone();
        v.push(Seg::Key(k));
        Self(v)
    }

    /// This path extended by an index.
    pub fn index(&self, i: usize) -> Self {
        let mut v = self.0.clone();
        v.push(Seg::Index(i));
        Self(v)
    }
}

impl fmt::Display for FieldPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, s) in self.0.iter().enumerate() {
            match s {
                Seg::Key(k) if i == 0 => write!(f, "{k}")?,
                Seg::Key(k) => write!(f, ".{k}")?,
                Seg::Index(n) => write!(f, "[{n}]")?,
            }
        }
        Ok(())
    }
}

/// One problem in a config file.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigError {
    pub file: PathBuf,
    /// 1-based line, when the field (or its table) is in the file.
    pub line: Option<usize>,
    /// Dotted path of the field, e.g. `joint[2].lever.p_mm`.
    pub field: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(l) = self.line {
            write!(f, ":{l}")?;
        }
        if self.field.is_empty() {
            write!(f, ": {}", self.message)
        } else {
            write!(f, ": {}: {}", self.field, self.message)
        }
    }
}

/// Every problem found in a config file (at least one).
#[derive(Debug, Clone, PartialEq)]
pub struct ConfigErrors(pub Vec<ConfigError>);

impl fmt::Display for ConfigErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ConfigErrors {}

/// 1-based line of a byte offset.
pub fn line_of(src: &str, offset: usize) -> usize {
    src.as_bytes()[..offset.min(src.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// The line of the deepest part of `path` present in the parsed document.
pub fn line_of_path(
    src: &str,
    doc: &toml::Spanned<DeTable<'_>>,
    path: &FieldPath,
) -> Option<usize> {
    let mut segs = path.0.iter();
    let Some(Seg::Key(first)) = segs.next() else {
        return None;
    };
    let mut node = doc.get_ref().get(*first)?;
    let mut best = line_of(src, node.span().start);
    for seg in segs {
        let next = match seg {
            Seg::Key(k) => node.get_ref().get(*k),
            Seg::Index(i) => node.get_ref().get(*i),
        };
        match next {
            Some(n) => {
                node = n;
                best = line_of(src, n.span().start);
            }
            None => break,
        }
    }
    Some(best)
}

/// Collects errors against one source file.
pub struct Collector<'a> {
    pub file: &'a Path,
    pub src: &'a str,
    pub doc: Option<toml::Spanned<DeTable<'a>>>,
    pub errors: Vec<ConfigError>,
}

impl<'a> Collector<'a> {
    pub fn new(file: &'a Path, src: &'a str) -> Self {
        Self {
            file,
            src,
            doc: DeTable::parse(src).ok(),
            errors: Vec::new(),
        }
    }

    /// Records an error at `path`.
    pub fn push(&mut self, path: &FieldPath, message: impl Into<String>) {
        let line = self
            .doc
            .as_ref()
            .and_then(|d| line_of_path(self.src, d, path));
        self.errors.push(ConfigError {
            file: self.file.to_path_buf(),
            line,
            field: path.to_string(),
            message: message.into(),
        });
    }
}
