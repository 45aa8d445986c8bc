//! Helpers shared by the end-to-end tests.

use std::path::{Path, PathBuf};

/// A binary of the workspace, next to this test's own executable's directory.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let dir = exe.parent().and_then(Path::parent).unwrap();
    let p = dir.join(name);
    assert!(
        p.exists(),
        "{} is not built: run `cargo build --workspace` (cargo test --workspace builds it)",
        p.display()
    );
    p
}
