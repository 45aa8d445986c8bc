//! Editing a rig config in place, as `rig calibrate --write` and `rig identify --apply` do:
//! through `toml_edit` (comments and layout kept), one joint's table at a time, and never
//! writing a file the config checker refuses.

use std::path::Path;

use crate::error::CliError;

/// The config at `path` as an editable document.
pub fn open(path: &Path) -> Result<toml_edit::DocumentMut, CliError> {
    let text = std::fs::read_to_string(path)?;
    text.parse()
        .map_err(|e| CliError::Invalid(format!("{}: not TOML: {e}", path.display())))
}

/// The `[[joint]]` table named `name`.
pub fn joint<'a>(
    doc: &'a mut toml_edit::DocumentMut,
    name: &str,
) -> Result<&'a mut toml_edit::Table, CliError> {
    doc.get_mut("joint")
        .and_then(toml_edit::Item::as_array_of_tables_mut)
        .and_then(|js| {
            js.iter_mut()
                .find(|t| t.get("name").and_then(|n| n.as_str()) == Some(name))
        })
        .ok_or_else(|| CliError::Invalid(format!("the config has no [[joint]] named {name:?}")))
}

/// Writes `text` to `path` once `rig_config` accepts it (checked in a file beside `path`,
/// which then replaces it): a refused edit leaves `path` as it was.
pub fn write_validated(path: &Path, text: &str) -> Result<(), CliError> {
    let tmp = path.with_extension("toml.edit-tmp");
    std::fs::write(&tmp, text)?;
    if let Err(e) = rig_config::load(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(e.into());
    }
    std::fs::rename(&tmp, path)?;
    Ok(())
}
