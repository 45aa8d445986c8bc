//! Request and reply on a serial line, as the protocol-1.0 client and the encoder bridge do
//! it: drop stale input, send the request, then gather what arrives until the reply is whole
//! or a deadline passes.

use std::io;
use std::time::Instant;

use serial2::SerialPort;

/// Drops what is waiting on the line (a late reply to an earlier request), then sends.
pub(crate) fn send(port: &SerialPort, request: &[u8]) -> io::Result<()> {
    port.discard_input_buffer()?;
    port.write_all(request)
}

/// Appends to `buf` what one read gets before `deadline`; `false` once the deadline has passed.
pub(crate) fn receive(
    port: &mut SerialPort,
    buf: &mut Vec<u8>,
    deadline: Instant,
) -> io::Result<bool> {
    let now = Instant::now();
    if now >= deadline {
        return Ok(false);
    }
    port.set_read_timeout(deadline - now)?;
    let mut chunk = [0u8; 64];
    match port.read(&mut chunk) {
        Ok(n) => buf.extend_from_slice(&chunk[..n]),
        Err(e) if e.kind() == io::ErrorKind::TimedOut => {}
        Err(e) => return Err(e),
    }
    Ok(true)
}
