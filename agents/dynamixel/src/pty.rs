//! A device on one end of a pseudo-terminal pair, for tests without hardware: a thread reads
//! what the client writes to the other end and answers it. The virtual servos and the virtual
//! encoder bridge are such devices.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use serial2::SerialPort;

/// A reply and the delay before it is sent.
pub type Reply = (Duration, Vec<u8>);

/// The device's thread; dropping it stops the thread.
#[derive(Debug)]
pub struct PtyDevice {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// A client end held open (see [`Self::hold_with_path`]).
    hold: Option<SerialPort>,
}

impl PtyDevice {
    /// Opens a pseudo-terminal pair and serves one end: `respond` gets the bytes received so
    /// far, removes those it has used, and returns the replies. Returns the client end.
    pub fn start(
        mut respond: impl FnMut(&mut Vec<u8>) -> Vec<Reply> + Send + 'static,
    ) -> std::io::Result<(Self, SerialPort)> {
        let (mut device, client) = SerialPort::pair()?;
        device.set_read_timeout(Duration::from_millis(20))?;
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut buf: Vec<u8> = Vec::new();
                let mut chunk = [0u8; 256];
                while !stop.load(Ordering::Relaxed) {
                    match device.read(&mut chunk) {
                        Ok(n) => buf.extend_from_slice(&chunk[..n]),
                        Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
                        // No client end open right now (EIO on a pseudo-terminal): wait for one.
                        Err(_) => {
                            std::thread::sleep(Duration::from_millis(10));
                            continue;
                        }
                    }
                    for (delay, bytes) in respond(&mut buf) {
                        if !delay.is_zero() {
                            std::thread::sleep(delay);
                        }
                        // A client that has gone may come back (another process): keep serving.
                        let _ = device.write_all(&bytes);
                    }
                }
            })
        };
        Ok((
            Self {
                stop,
                thread: Some(thread),
                hold: None,
            },
            client,
        ))
    }

    /// Holds `client` open (unread) and returns its device path (e.g. /dev/pts/3) for
    /// another process to open. While one client end is open, another process closing its
    /// own does not hang the line up, and the device node stays. Linux only (/proc).
    pub fn hold_with_path(&mut self, client: SerialPort) -> std::io::Result<PathBuf> {
        let fd = std::os::unix::io::AsRawFd::as_raw_fd(&client);
        let path = std::fs::read_link(format!("/proc/self/fd/{fd}"))?;
        self.hold = Some(client);
        Ok(path)
    }
}

impl Drop for PtyDevice {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
