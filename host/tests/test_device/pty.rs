//! Pseudo-terminals as serial ports: opening one behind a path, a port that is not a
//! Tangent, and a relay with faults between the host and another serial peer.

use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::os::fd::FromRawFd;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Faults applied to every byte (per mille).
#[derive(Debug, Clone, Copy, Default)]
pub struct Faults {
    /// Device → host bytes dropped.
    pub drop_out: u32,
    /// Device → host bytes corrupted (XOR with a random non-zero value).
    pub corrupt_out: u32,
    /// Host → device bytes dropped.
    pub drop_in: u32,
    /// Host → device bytes corrupted.
    pub corrupt_in: u32,
}

/// A port that is not a Tangent: a GPS-like device sending NMEA text.
pub struct NotATangent {
    path: PathBuf,
    stop: Arc<Mutex<bool>>,
    thread: Option<JoinHandle<()>>,
    _dir: tempfile::TempDir,
}

impl NotATangent {
    /// Starts it; [`NotATangent::path`] is where the host opens it.
    pub fn start() -> NotATangent {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ttyGPS");
        let mut pty = open_pty(&path);
        let stop = Arc::new(Mutex::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 256];
            while !*s.lock().unwrap() {
                // What the host sends is ignored.
                let _ = pty.master.read(&mut buf);
                let _ = pty.master.write_all(
                    b"$GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,*76\r\n",
                );
                std::thread::sleep(Duration::from_millis(50));
            }
        });
        NotATangent {
            path,
            stop,
            thread: Some(thread),
            _dir: dir,
        }
    }

    /// The path to open.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for NotATangent {
    fn drop(&mut self) {
        *self.stop.lock().unwrap() = true;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

pub(super) struct Pty {
    pub(super) master: File,
}

pub(super) fn open_pty(link: &Path) -> Pty {
    let pty = nix::pty::openpty(None, None).expect("openpty");
    // openpty(3) does not set close-on-exec: without it a child process (the `tangent`
    // binary under test) would inherit the master, and closing ours would not hang up.
    for fd in [pty.master, pty.slave] {
        nix::fcntl::fcntl(
            fd,
            nix::fcntl::FcntlArg::F_SETFD(nix::fcntl::FdFlag::FD_CLOEXEC),
        )
        .expect("close-on-exec");
    }
    let mut t = nix::sys::termios::tcgetattr(pty.slave).expect("tcgetattr");
    nix::sys::termios::cfmakeraw(&mut t);
    nix::sys::termios::tcsetattr(pty.slave, nix::sys::termios::SetArg::TCSANOW, &t)
        .expect("tcsetattr");
    let name = std::fs::read_link(format!("/proc/self/fd/{}", pty.slave)).expect("pty name");
    nix::fcntl::fcntl(
        pty.master,
        nix::fcntl::FcntlArg::F_SETFL(nix::fcntl::OFlag::O_NONBLOCK),
    )
    .expect("non-blocking master");
    // Our copy of the slave is not needed: the host opens it by name.
    let _ = nix::unistd::close(pty.slave);
    // Replace the link atomically (new link, then rename over the old one).
    let tmp = link.with_extension("new");
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(&name, &tmp).expect("symlink");
    std::fs::rename(&tmp, link).expect("rename symlink");
    Pty {
        // SAFETY: `openpty` returned a fresh descriptor that nothing else owns.
        master: unsafe { File::from_raw_fd(pty.master) },
    }
}

/// What the test controls of a [`Relay`].
#[derive(Default)]
struct RelayControl {
    faults: Faults,
    cut_until: Option<Instant>,
    stop: bool,
}

/// A man in the middle between the host and a real serial peer (the emulated firmware's
/// pty): the host opens [`Relay::path`]; bytes are copied both ways with [`Faults`], and
/// [`Relay::cut`] unplugs the host side for a while, as [`super::TestDevice::cut`] does.
pub struct Relay {
    path: PathBuf,
    control: Arc<Mutex<RelayControl>>,
    thread: Option<JoinHandle<()>>,
    _dir: tempfile::TempDir,
}

impl Relay {
    /// Relays to the tty at `peer`.
    pub fn start(peer: &Path) -> Relay {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ttyRELAY");
        let control = Arc::new(Mutex::new(RelayControl::default()));
        let fd = nix::fcntl::open(
            peer,
            nix::fcntl::OFlag::O_RDWR
                | nix::fcntl::OFlag::O_NOCTTY
                | nix::fcntl::OFlag::O_NONBLOCK
                | nix::fcntl::OFlag::O_CLOEXEC,
            nix::sys::stat::Mode::empty(),
        )
        .expect("open the peer tty");
        let mut t = nix::sys::termios::tcgetattr(fd).expect("tcgetattr");
        nix::sys::termios::cfmakeraw(&mut t);
        nix::sys::termios::tcsetattr(fd, nix::sys::termios::SetArg::TCSANOW, &t).expect("raw");
        // SAFETY: a fresh descriptor owned by nothing else.
        let mut peer_file = unsafe { File::from_raw_fd(fd) };
        let mut pty = open_pty(&path);
        let c = control.clone();
        let p = path.clone();
        let thread = std::thread::spawn(move || {
            let mut rng = 0x9E37_79B9u32;
            let mut hit = |per_mille: u32| {
                rng ^= rng << 13;
                rng ^= rng >> 17;
                rng ^= rng << 5;
                per_mille > 0 && rng % 1000 < per_mille
            };
            let mut buf = [0u8; 1024];
            loop {
                let (stop, cut_until, f) = {
                    let mut c = c.lock().unwrap();
                    (c.stop, c.cut_until.take(), c.faults)
                };
                if stop {
                    return;
                }
                if let Some(until) = cut_until {
                    drop(pty);
                    let _ = std::fs::remove_file(&p);
                    while Instant::now() < until {
                        // The device keeps talking into the void.
                        let _ = peer_file.read(&mut buf);
                        std::thread::sleep(Duration::from_millis(1));
                    }
                    pty = open_pty(&p);
                }
                let mut idle = true;
                // Host → device.
                if let Ok(n) = pty.master.read(&mut buf) {
                    idle = n == 0;
                    let mut out = Vec::with_capacity(n);
                    for &b in &buf[..n] {
                        if hit(f.drop_in) {
                            continue;
                        }
                        out.push(if hit(f.corrupt_in) { b ^ 0x5A } else { b });
                    }
                    write_all_nb(&mut peer_file, &out);
                }
                // Device → host.
                if let Ok(n) = peer_file.read(&mut buf) {
                    idle &= n == 0;
                    let mut out = Vec::with_capacity(n);
                    for &b in &buf[..n] {
                        if hit(f.drop_out) {
                            continue;
                        }
                        out.push(if hit(f.corrupt_out) { b ^ 0x5A } else { b });
                    }
                    write_all_nb(&mut pty.master, &out);
                }
                if idle {
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        });
        Relay {
            path,
            control,
            thread: Some(thread),
            _dir: dir,
        }
    }

    /// The path the host opens.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Sets the faults.
    pub fn faults(&self, f: Faults) {
        self.control.lock().unwrap().faults = f;
    }

    /// Unplugs the host side for `d`.
    pub fn cut(&self, d: Duration) {
        self.control.lock().unwrap().cut_until = Some(Instant::now() + d);
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.control.lock().unwrap().stop = true;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Writes everything to a non-blocking descriptor (gives up after 500 ms or on a hang-up:
/// the bytes are lost as on a wire).
fn write_all_nb(f: &mut File, bytes: &[u8]) {
    let mut rest = bytes;
    let deadline = Instant::now() + Duration::from_millis(500);
    while !rest.is_empty() && Instant::now() < deadline {
        match f.write(rest) {
            Ok(n) => rest = &rest[n..],
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(1))
            }
            Err(_) => return,
        }
    }
}
