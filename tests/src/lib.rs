//! End-to-end tests of the rig, in `tests/tests/`. They cross process and language
//! boundaries: the wire format decoded by a Python client that shares no code with Rust
//! (`wire_python.rs`); later, agents as separate processes over loopback Zenoh.
//!
//! The `rig` command's own end-to-end tests live beside it in `agents/rig/tests/`, where
//! Cargo provides the path of the built binary.
