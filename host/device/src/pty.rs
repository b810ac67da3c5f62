//! A pseudo-terminal pair for the virtual luminaire (POSIX `openpty(3)`, raw mode per
//! `cfmakeraw(3)`).
//!
//! The emulator owns the master side and serves the luminaire protocol on it; clients open the
//! slave path (`/dev/pts/N`) exactly like a USB CDC-ACM port, through `serialport`. The pair keeps
//! its own handle on the slave open for its whole life so that a client closing the port (or
//! dying mid-command) does not hang the line up: the master then never sees `EIO`, and the next
//! client can simply reopen the path.

use std::fs::File;
use std::io;
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::Duration;

use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

/// Error creating or using the pseudo-terminal.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PtyError {
    /// `openpty` failed (no free pseudo-terminals, no `/dev/ptmx`).
    #[error("cannot open a pseudo-terminal")]
    Open(#[source] nix::Error),
    /// Switching the slave to raw mode failed.
    #[error("cannot put the pseudo-terminal into raw mode")]
    RawMode(#[source] nix::Error),
    /// The slave's device path could not be determined.
    #[error("cannot name the pseudo-terminal's slave device")]
    SlavePath(#[source] nix::Error),
    /// Reading, writing or waiting on the master failed.
    #[error("pseudo-terminal I/O failed")]
    Io(#[from] io::Error),
}

/// A raw-mode pseudo-terminal: the master side for the emulator, a path for clients.
#[derive(Debug)]
pub struct PseudoTerminal {
    master: File,
    /// Held open only so the line never hangs up between clients.
    _slave: OwnedFd,
    slave_path: PathBuf,
}

impl PseudoTerminal {
    /// Opens a new pair and puts the slave into raw mode (no echo, no line editing, 8 bits).
    pub fn open() -> Result<Self, PtyError> {
        let pair = nix::pty::openpty(None, None).map_err(PtyError::Open)?;
        let mut termios = tcgetattr(pair.slave.as_fd()).map_err(PtyError::RawMode)?;
        cfmakeraw(&mut termios);
        tcsetattr(pair.slave.as_fd(), SetArg::TCSANOW, &termios).map_err(PtyError::RawMode)?;
        let slave_path = nix::unistd::ttyname(pair.slave.as_fd()).map_err(PtyError::SlavePath)?;
        // Non-blocking master: a client that never reads must not stall the emulator.
        let flags = fcntl(pair.master.as_fd(), FcntlArg::F_GETFL).map_err(PtyError::Open)?;
        let flags = OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK;
        fcntl(pair.master.as_fd(), FcntlArg::F_SETFL(flags)).map_err(PtyError::Open)?;
        Ok(Self {
            master: File::from(pair.master),
            _slave: pair.slave,
            slave_path,
        })
    }

    /// Path clients open, e.g. `/dev/pts/7`.
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }

    /// Waits up to `timeout` for bytes from a client; true when a read will not block.
    pub fn wait_readable(&self, timeout: Duration) -> Result<bool, PtyError> {
        let millis = u16::try_from(timeout.as_millis()).unwrap_or(u16::MAX);
        let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
        match poll(&mut fds, PollTimeout::from(millis)) {
            Ok(n) => Ok(n > 0
                && fds[0]
                    .revents()
                    .is_some_and(|r| r.contains(PollFlags::POLLIN))),
            Err(nix::Error::EINTR) => Ok(false),
            Err(err) => Err(PtyError::Io(err.into())),
        }
    }

    /// The (non-blocking) master side: read what clients wrote, write what they will read.
    pub fn master(&mut self) -> &mut File {
        &mut self.master
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read, Write};

    #[test]
    fn bytes_pass_both_ways_unaltered() {
        let mut pty = PseudoTerminal::open().unwrap();
        assert!(pty.slave_path().starts_with("/dev/pts"));
        let mut client = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(pty.slave_path())
            .unwrap();
        // Raw mode: a NUL, CR and LF, and a ^C pass through untouched and are not echoed.
        let payload = [0u8, b'\r', b'\n', 0x03, 0xff];
        client.write_all(&payload).unwrap();
        assert!(pty.wait_readable(Duration::from_secs(2)).unwrap());
        let mut got = [0u8; 5];
        pty.master().read_exact(&mut got).unwrap();
        assert_eq!(got, payload);
        pty.master().write_all(&payload).unwrap();
        let mut back = [0u8; 5];
        client.read_exact(&mut back).unwrap();
        assert_eq!(back, payload);
    }

    #[test]
    fn line_survives_a_client_closing() {
        let mut pty = PseudoTerminal::open().unwrap();
        drop(std::fs::File::open(pty.slave_path()).unwrap());
        // No hang-up: nothing to read, and no error.
        assert!(!pty.wait_readable(Duration::from_millis(20)).unwrap());
        let mut client = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(pty.slave_path())
            .unwrap();
        client.write_all(b"x").unwrap();
        assert!(pty.wait_readable(Duration::from_secs(2)).unwrap());
        let mut got = [0u8; 1];
        pty.master().read_exact(&mut got).unwrap();
        assert_eq!(&got, b"x");
    }
}
