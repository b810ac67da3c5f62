//! The byte link to a luminaire: a USB CDC-ACM serial port (or the virtual luminaire's
//! pseudo-terminal) opened through `serialport`.
//!
//! CDC-ACM ignores the line settings, so the baud rate is nominal. Frames are delimited by the
//! protocol's framing, not by timing: the link only moves bytes and waits with a deadline.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

use serialport::{ClearBuffer, SerialPort};

/// Nominal line rate; USB CDC-ACM devices ignore it.
pub const NOMINAL_BAUD: u32 = 115_200;

/// Error opening the serial port.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OpenError {
    /// The path does not exist (device unplugged, emulator not running).
    #[error("no device at {path}")]
    NotFound {
        /// The path that was tried.
        path: PathBuf,
    },
    /// Another program holds the port open exclusively.
    #[error("{path} is busy: another program has it open")]
    Busy {
        /// The path that was tried.
        path: PathBuf,
    },
    /// Any other failure to open or configure the port.
    #[error("cannot open {path}")]
    Other {
        /// The path that was tried.
        path: PathBuf,
        /// What `serialport` reported.
        #[source]
        source: serialport::Error,
    },
}

/// A byte link with deadlines: what the device client needs from a port.
pub trait Link {
    /// Writes all of `bytes` and flushes them to the device.
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Reads whatever arrives within `timeout` into `buf`; `Ok(0)` when nothing arrived.
    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
    /// Drops any bytes received but not yet read (stale replies from an earlier session).
    fn discard_input(&mut self) -> io::Result<()>;
}

/// A serial port opened through `serialport`.
pub struct SerialLink {
    port: Box<dyn SerialPort>,
    path: PathBuf,
}

impl std::fmt::Debug for SerialLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialLink")
            .field("path", &self.path)
            .finish()
    }
}

impl SerialLink {
    /// Opens `path` (8N1, nominal baud, no flow control) and drops stale input.
    pub fn open(path: &Path) -> Result<Self, OpenError> {
        let name = path.to_string_lossy();
        let port = serialport::new(name.as_ref(), NOMINAL_BAUD)
            .timeout(Duration::from_millis(100))
            .open()
            .map_err(|source| classify_open_error(path, source))?;
        let mut link = Self {
            port,
            path: path.to_path_buf(),
        };
        link.discard_input().map_err(|err| OpenError::Other {
            path: path.to_path_buf(),
            source: err.into(),
        })?;
        Ok(link)
    }

    /// The path this link was opened on.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

fn classify_open_error(path: &Path, source: serialport::Error) -> OpenError {
    let path = path.to_path_buf();
    match source.kind() {
        serialport::ErrorKind::NoDevice => OpenError::NotFound { path },
        serialport::ErrorKind::Io(io::ErrorKind::NotFound) => OpenError::NotFound { path },
        serialport::ErrorKind::Io(io::ErrorKind::ResourceBusy) => OpenError::Busy { path },
        _ if source.description.contains("busy") => OpenError::Busy { path },
        _ => OpenError::Other { path, source },
    }
}

impl Link for SerialLink {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.port.write_all(bytes)?;
        self.port.flush()
    }

    fn receive(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        // serialport rejects a zero timeout on some platforms; poll for at least 1 ms.
        self.port
            .set_timeout(timeout.max(Duration::from_millis(1)))
            .map_err(io::Error::from)?;
        match self.port.read(buf) {
            Ok(n) => Ok(n),
            Err(err) if err.kind() == io::ErrorKind::TimedOut => Ok(0),
            Err(err) if err.kind() == io::ErrorKind::Interrupted => Ok(0),
            Err(err) => Err(err),
        }
    }

    fn discard_input(&mut self) -> io::Result<()> {
        self.port.clear(ClearBuffer::Input).map_err(io::Error::from)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn serial_link_talks_to_a_pty() {
        use crate::pty::PseudoTerminal;
        let mut pty = PseudoTerminal::open().unwrap();
        let mut link = SerialLink::open(pty.slave_path()).unwrap();
        link.send(b"hello").unwrap();
        assert!(pty.wait_readable(Duration::from_secs(2)).unwrap());
        let mut got = [0u8; 5];
        pty.master().read_exact(&mut got).unwrap();
        assert_eq!(&got, b"hello");
        pty.master().write_all(b"world").unwrap();
        let mut buf = [0u8; 16];
        let mut received = Vec::new();
        while received.len() < 5 {
            let n = link.receive(&mut buf, Duration::from_secs(2)).unwrap();
            assert!(n > 0, "timed out");
            received.extend_from_slice(&buf[..n]);
        }
        assert_eq!(received, b"world");
        assert_eq!(
            link.receive(&mut buf, Duration::from_millis(10)).unwrap(),
            0
        );
    }

    #[test]
    fn missing_port_is_not_found() {
        let err = SerialLink::open(Path::new("/dev/meb-no-such-port")).unwrap_err();
        assert!(matches!(err, OpenError::NotFound { .. }), "{err:?}");
    }
}
