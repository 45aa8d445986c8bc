//! The one table of message kinds. Adding a kind is one row here, its type in the module of
//! its direction (`messages::{joint, estimate, allocation, sim}`), and its row in `WIRE.md`
//! (a test checks the two tables agree) and in the Python decoder.
//!
//! Each row: the kind byte (byte 3 of the header), the message type, the module of its
//! direction, and the body's Python `struct` format as `WIRE.md` gives it (a variable tail
//! after the fixed part is written after a `+`). The table is a macro that hands its rows to
//! a generator: `kind.rs` makes [`Kind`](crate::Kind) from it (bytes and names only, so the
//! envelope needs no message type) and `messages` makes `AnyMessage` and `decode_any`.

macro_rules! wire_table {
    ($generate:ident) => {
        $generate! {
            1 JointSample       joint      "<HHQQdddddd",
            2 JointCommand      joint      "<HHQQdddB",
            3 JointStatus       joint      "<HBQQH + utf8",
            4 JointEstimate     estimate   "<HHQQddddddd",
            5 EeEstimate        estimate   "<HIQQdddddddd",
            6 AllocationRequest allocation "<QddBddd",
            7 AllocationResult  allocation "<QBddddddd + B n*d n*d H utf8",
            8 SimTruth          sim        "<HQQdddd",
            9 BoardSample       joint      "<H + n*HHQQdddddd",
        }
    };
}

pub(crate) use wire_table;
