//! Each message as JSON, with a JSON Schema per kind (feature `json`): the encoding of the
//! rig's MCAP recordings, which Foxglove, PlotJuggler and any JSON reader open without a
//! plugin. The conversion is lossless: numbers are written in their shortest form that reads
//! back to the same `f64` (integers exactly), so a message read back from JSON encodes to the
//! same wire bytes (tested for every kind). Field names carry their units (`deflection_rad`,
//! `t_acq_ns`). JavaScript readers hold numbers as doubles: a nanosecond stamp there keeps
//! about 0.25 µs — a viewer's concern, not the recording's.

use thiserror::Error;

use crate::kind::Kind;
use crate::messages::{AnyMessage, Message, allocation, encode, estimate, joint, sim};
use crate::table::wire_table;
use crate::validation::ValidationError;

/// Why JSON is not a message.
#[derive(Debug, Error)]
pub enum JsonError {
    #[error("not a {kind} in JSON: {source}")]
    Syntax {
        kind: &'static str,
        #[source]
        source: serde_json::Error,
    },
    #[error(transparent)]
    Invalid(#[from] ValidationError),
}

fn read<M: Message + serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<M, JsonError> {
    let m: M = serde_json::from_slice(bytes).map_err(|source| JsonError::Syntax {
        kind: M::KIND.name(),
        source,
    })?;
    m.validate()?;
    Ok(m)
}

/// A self-contained JSON Schema (draft 7, no references) of `M`, titled with its MCAP name.
fn schema<M: schemars::JsonSchema>() -> String {
    let settings = schemars::generate::SchemaSettings::draft07().with(|s| {
        s.inline_subschemas = true;
    });
    let schema = settings.into_generator().into_root_schema_for::<M>();
    serde_json::to_string_pretty(&schema).unwrap_or_default()
}

macro_rules! generate_json {
    ($($byte:literal $name:ident $direction:ident $format:literal,)*) => {
        /// The message as JSON (one object, its fields by name).
        pub fn to_json(m: &AnyMessage) -> Vec<u8> {
            // Serialising plain structs of numbers, strings and lists cannot fail.
            match m {
                $(AnyMessage::$name(m) => serde_json::to_vec(m).unwrap_or_default(),)*
            }
        }

        /// A message of `kind` from its JSON, validated as a decoded wire message is.
        pub fn from_json(kind: Kind, bytes: &[u8]) -> Result<AnyMessage, JsonError> {
            Ok(match kind {
                $(Kind::$name => AnyMessage::$name(read::<$direction::$name>(bytes)?),)*
            })
        }

        /// The JSON Schema of `kind`'s messages.
        pub fn json_schema(kind: Kind) -> String {
            match kind {
                $(Kind::$name => schema::<$direction::$name>(),)*
            }
        }

        /// Validates and encodes any message to its wire bytes.
        pub fn encode_any(m: &AnyMessage) -> Result<Vec<u8>, ValidationError> {
            match m {
                $(AnyMessage::$name(m) => encode(m),)*
            }
        }
    };
}

wire_table!(generate_json);

/// The MCAP schema name of a kind: `rig.<Kind>`.
pub fn schema_name(kind: Kind) -> String {
    format!("rig.{}", kind.name())
}

/// The kind a `rig.<Kind>` schema name names.
pub fn kind_of_schema(name: &str) -> Option<Kind> {
    let name = name.strip_prefix("rig.")?;
    Kind::ALL.iter().copied().find(|k| k.name() == name)
}
