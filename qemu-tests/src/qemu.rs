//! One QEMU session running the firmware.
//!
//! ```text
//! qemu-system-arm -machine mps2-an386 -nographic -monitor none
//!     -semihosting-config enable=on,target=native -icount shift=0
//!     -serial tcp:127.0.0.1:<port>,nodelay=on -kernel <elf>
//! ```
//!
//! The harness listens on a loopback port of its own choosing (port 0) before starting QEMU, so there is
//! no race: QEMU connects UART0 to it as a client. Semihosting output (the defmt stream) arrives on QEMU's
//! stdout, and QEMU's own messages on stderr; both are drained by threads so QEMU never blocks on a pipe.
//! Every wait is bounded by the session's deadline, and [`Drop`] kills QEMU if it is still running.

use crate::logs::{self, LogLine};
use crate::HilError;
use shared_types::protocol::{
    decode_frame, encode_frame, FrameEvent, Reader, Reply, Request, State, MAX_FRAME,
};
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The QEMU binary: `$QEMU_SYSTEM_ARM`, else `qemu-system-arm` from `PATH`.
pub fn qemu_binary() -> PathBuf {
    std::env::var_os("QEMU_SYSTEM_ARM")
        .map(PathBuf::from)
        .unwrap_or_else(|| "qemu-system-arm".into())
}

/// Default bound on one whole session.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(120);

/// How a session ended.
#[derive(Debug)]
pub struct Exit {
    /// QEMU's exit code (the firmware's semihosting exit code), `None` if killed by a signal.
    pub code: Option<i32>,
    /// The decoded defmt log.
    pub logs: Vec<LogLine>,
}

/// A running QEMU with the firmware.
pub struct Qemu {
    child: Child,
    uart: TcpStream,
    rx: VecDeque<u8>,
    reader: Reader,
    stdout: Arc<Mutex<Vec<u8>>>,
    stderr: Arc<Mutex<Vec<u8>>>,
    drains: Vec<JoinHandle<()>>,
    started: Instant,
    deadline: Instant,
    elf: PathBuf,
}

fn drain(mut from: impl Read + Send + 'static, into: Arc<Mutex<Vec<u8>>>) -> JoinHandle<()> {
    std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        loop {
            match from.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(k) => into
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .extend_from_slice(&buf[..k]),
            }
        }
    })
}

impl Qemu {
    /// Boots `elf`; the whole session (every later wait included) must end within `timeout`.
    pub fn launch(elf: &Path, timeout: Duration) -> Result<Qemu, HilError> {
        let started = Instant::now();
        let deadline = started + timeout;
        let listener =
            TcpListener::bind("127.0.0.1:0").map_err(HilError::io("binding a loopback port"))?;
        let port = listener
            .local_addr()
            .map_err(HilError::io("reading the port"))?
            .port();
        listener
            .set_nonblocking(true)
            .map_err(HilError::io("configuring the listener"))?;
        let qemu = qemu_binary();
        let mut child = Command::new(&qemu)
            .args(["-machine", "mps2-an386", "-nographic", "-monitor", "none"])
            .args(["-semihosting-config", "enable=on,target=native", "-icount", "shift=0"])
            // nodelay: without it Nagle + delayed ACKs cost ~40 ms per request/reply exchange.
            .args(["-serial", &format!("tcp:127.0.0.1:{port},nodelay=on")])
            .arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(HilError::io(format!(
                "starting {} (install it with `cargo xtask test`, or `apt-get install qemu-system-arm`)",
                qemu.display()
            )))?;
        let stdout = Arc::new(Mutex::new(Vec::new()));
        let stderr = Arc::new(Mutex::new(Vec::new()));
        let mut drains = Vec::new();
        if let Some(o) = child.stdout.take() {
            drains.push(drain(o, stdout.clone()));
        }
        if let Some(e) = child.stderr.take() {
            drains.push(drain(e, stderr.clone()));
        }
        // From here on, `Qemu`'s Drop kills the child on every error path.
        let uart = loop {
            match listener.accept() {
                Ok((s, _)) => break Ok(s),
                Err(e) if e.kind() == ErrorKind::WouldBlock => {}
                Err(e) => break Err(HilError::io("accepting QEMU's UART connection")(e)),
            }
            if let Ok(Some(status)) = child.try_wait() {
                let err = stderr
                    .lock()
                    .map(|v| String::from_utf8_lossy(&v).into_owned())
                    .unwrap_or_default();
                break Err(HilError::QemuExited {
                    status: status.to_string(),
                    what: "connecting UART0".into(),
                    stderr: err,
                });
            }
            if Instant::now() >= deadline {
                break Err(HilError::Timeout {
                    what: "QEMU to connect UART0".into(),
                    after: timeout,
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        let uart = match uart {
            Ok(s) => s,
            Err(e) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(e);
            }
        };
        uart.set_nodelay(true)
            .map_err(HilError::io("configuring the UART socket"))?;
        uart.set_nonblocking(false)
            .map_err(HilError::io("configuring the UART socket"))?;
        Ok(Qemu {
            child,
            uart,
            rx: VecDeque::new(),
            reader: Reader::new(),
            stdout,
            stderr,
            drains,
            started,
            deadline,
            elf: elf.to_path_buf(),
        })
    }

    fn remaining(&self, what: &str) -> Result<Duration, HilError> {
        let left = self.deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            Err(HilError::Timeout {
                what: what.into(),
                after: self.deadline - self.started,
            })
        } else {
            Ok(left)
        }
    }

    fn stderr_text(&self) -> String {
        self.stderr
            .lock()
            .map(|v| String::from_utf8_lossy(&v).into_owned())
            .unwrap_or_default()
    }

    fn exited(&mut self, what: &str) -> HilError {
        // Give QEMU a moment to finish exiting so that its status is known.
        let status = (0..100)
            .find_map(|_| match self.child.try_wait() {
                Ok(Some(s)) => Some(s.to_string()),
                _ => {
                    std::thread::sleep(Duration::from_millis(10));
                    None
                }
            })
            .unwrap_or_else(|| "still running, UART closed".into());
        HilError::QemuExited {
            status,
            what: what.into(),
            stderr: self.stderr_text(),
        }
    }

    /// Sends raw bytes on UART0 (for malformed-frame tests).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), HilError> {
        let left = self.remaining("sending on UART0")?;
        self.uart
            .set_write_timeout(Some(left))
            .map_err(HilError::io("setting the UART timeout"))?;
        if let Err(e) = self.uart.write_all(bytes) {
            return Err(match e.kind() {
                ErrorKind::BrokenPipe | ErrorKind::ConnectionReset => {
                    self.exited("sending on UART0")
                }
                _ => HilError::io("sending on UART0")(e),
            });
        }
        Ok(())
    }

    /// Sends one request frame.
    pub fn send(&mut self, req: &Request) -> Result<(), HilError> {
        let mut buf = [0u8; MAX_FRAME];
        let frame = encode_frame(req, &mut buf).map_err(HilError::Protocol)?;
        let frame = frame.to_vec();
        self.send_raw(&frame)
    }

    /// Waits for the next reply frame (strictly decoded).
    pub fn recv(&mut self) -> Result<Reply, HilError> {
        loop {
            while let Some(b) = self.rx.pop_front() {
                match self.reader.push(b) {
                    Some(FrameEvent::Frame(f)) => {
                        return decode_frame::<Reply>(f).map_err(HilError::Protocol)
                    }
                    Some(FrameEvent::Oversize) => {
                        return Err(HilError::Protocol(
                            shared_types::protocol::FrameError::Oversize,
                        ))
                    }
                    None => {}
                }
            }
            let left = self.remaining("a reply on UART0")?;
            self.uart
                .set_read_timeout(Some(left))
                .map_err(HilError::io("setting the UART timeout"))?;
            let mut buf = [0u8; 1024];
            match self.uart.read(&mut buf) {
                Ok(0) => return Err(self.exited("waiting for a reply")),
                Ok(k) => self.rx.extend(&buf[..k]),
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return Err(HilError::Timeout {
                        what: "a reply on UART0".into(),
                        after: self.deadline - self.started,
                    })
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(HilError::io("reading UART0")(e)),
            }
        }
    }

    /// Sends `Step { seq, x }` and waits for the reply.
    pub fn step(&mut self, seq: u32, x: &[f32]) -> Result<Reply, HilError> {
        let x = State::from_slice(x).ok_or_else(|| {
            HilError::Check(format!("state of dimension {} exceeds MAX_N", x.len()))
        })?;
        self.send(&Request::Step { seq, x })?;
        self.recv()
    }

    /// The defmt log so far.
    pub fn logs(&self) -> Result<Vec<LogLine>, HilError> {
        let elf = std::fs::read(&self.elf)
            .map_err(HilError::io(format!("reading {}", self.elf.display())))?;
        let stream = self.stdout.lock().map(|v| v.clone()).unwrap_or_default();
        logs::decode(&elf, &stream)
    }

    /// Waits (within the deadline) for QEMU to exit by itself, then returns its code and the whole log.
    pub fn wait(mut self) -> Result<Exit, HilError> {
        let status: ExitStatus = loop {
            match self
                .child
                .try_wait()
                .map_err(HilError::io("waiting for QEMU"))?
            {
                Some(s) => break s,
                None => {
                    self.remaining("QEMU to exit")?;
                    std::thread::sleep(Duration::from_millis(5));
                }
            }
        };
        for d in self.drains.drain(..) {
            let _ = d.join();
        }
        let logs = self.logs()?;
        if let Some(peak) = logs::stack_peak(&logs) {
            logs::record_stack_peak(&self.elf, peak);
        }
        Ok(Exit {
            code: status.code(),
            logs,
        })
    }

    /// Sends `Shutdown` and waits for QEMU to exit.
    pub fn shutdown(mut self) -> Result<Exit, HilError> {
        self.send(&Request::Shutdown)?;
        self.wait()
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
        for d in self.drains.drain(..) {
            let _ = d.join();
        }
    }
}
