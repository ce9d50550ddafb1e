//! The firmware binary under `qemu-system-arm` (issue mode b, PIL): the
//! `mps2-an386` board build of `firmware/boards/qemu` boots with its UART
//! on a pty, and [`crate::serial::SerialLink`] speaks the wire protocol to
//! it exactly as to a real board.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Process, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use crate::SimError;
use crate::firmware::Link;
use crate::serial::SerialLink;
use ocm_shared::protocol::{Command, Reply};

/// The Cortex-M4F target the board is built for.
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// The environment variable naming the checkout whose `firmware/boards/qemu` is built for PIL.
pub const SOURCE_DIR_ENV: &str = "OCM_SOURCE_DIR";

/// The checkout holding the board sources: `OCM_SOURCE_DIR`, else the nearest directory at or
/// above the current one that holds `firmware/boards/qemu/Cargo.toml`. An installed binary
/// carries no path of the machine it was built on, so a user outside a checkout is told what to
/// set.
pub fn repo_root() -> Result<PathBuf, SimError> {
    let marker = Path::new("firmware/boards/qemu/Cargo.toml");
    if let Some(dir) = std::env::var_os(SOURCE_DIR_ENV).filter(|v| !v.is_empty()) {
        let dir = PathBuf::from(dir);
        return if dir.join(marker).is_file() {
            Ok(dir)
        } else {
            Err(io(
                &dir,
                format!(
                    "{SOURCE_DIR_ENV} names no ocm checkout (no {})",
                    marker.display()
                ),
            ))
        };
    }
    let start = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
    start
        .ancestors()
        .find(|a| a.join(marker).is_file())
        .map(Path::to_path_buf)
        .ok_or_else(|| {
            io(
                &start,
                format!(
                    "the QEMU board is built from an ocm checkout: run from inside one, or set \
                     {SOURCE_DIR_ENV} to its root"
                ),
            )
        })
}

fn io(path: &Path, message: String) -> SimError {
    SimError::Io {
        path: path.display().to_string(),
        message,
    }
}

/// Whether `qemu-system-arm` can be started.
pub fn qemu_available() -> bool {
    Process::new("qemu-system-arm")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Builds the QEMU board binary (release, `target-boards/` under the
/// repository) and returns the ELF's path. Cargo makes this a no-op when
/// nothing changed.
pub fn build_board() -> Result<PathBuf, SimError> {
    let root = repo_root()?;
    let board = root.join("firmware/boards/qemu");
    let target_dir = root.join("target-boards");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Process::new(cargo)
        .current_dir(&board)
        .env("CARGO_TARGET_DIR", &target_dir)
        .args(["build", "--release", "--bin", "ocm-qemu"])
        .output()
        .map_err(|e| io(&board, format!("cannot run cargo: {e}")))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let hint = if err.contains("may not be installed") || err.contains("can't find crate") {
            format!(" (install the target: rustup target add {TARGET})")
        } else {
            String::new()
        };
        return Err(io(
            &board,
            format!("building the QEMU board failed{hint}:\n{err}"),
        ));
    }
    Ok(target_dir.join(TARGET).join("release/ocm-qemu"))
}

/// The board binary for a PIL run, built if needed; `Ok(Err(why))` when
/// this machine cannot run one (no qemu-system-arm, no Cortex-M target),
/// so that callers can skip with the reason.
pub fn board_for_pil() -> Result<Result<PathBuf, String>, SimError> {
    if !qemu_available() {
        return Ok(Err(
            "qemu-system-arm not found (apt-get install qemu-system-arm)".into(),
        ));
    }
    match build_board() {
        Ok(elf) => Ok(Ok(elf)),
        Err(SimError::Io { message, .. }) if message.contains("rustup target add") => {
            Ok(Err(message))
        }
        Err(e) => Err(e),
    }
}

/// A running QEMU with the firmware; killed on drop.
pub struct QemuBoard {
    child: Child,
    pty: String,
}

impl QemuBoard {
    /// Boots `elf` on the `mps2-an386` machine and waits for QEMU to name
    /// the pty of the board's UART.
    pub fn boot(elf: &Path) -> Result<Self, SimError> {
        if !elf.is_file() {
            return Err(io(elf, "no such firmware ELF".into()));
        }
        let mut child = Process::new("qemu-system-arm")
            .args(["-cpu", "cortex-m4", "-machine", "mps2-an386"])
            .args(["-display", "none", "-monitor", "none"])
            .args(["-semihosting-config", "enable=on,target=native"])
            .args(["-serial", "pty", "-kernel"])
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| {
                io(
                    elf,
                    format!("cannot start qemu-system-arm ({e}); install it with apt-get install qemu-system-arm"),
                )
            })?;
        // QEMU announces the pty on stderr (older versions: stdout).
        let (tx, rx) = mpsc::channel();
        let streams: Vec<Box<dyn Read + Send>> = [
            child
                .stderr
                .take()
                .map(|s| Box::new(s) as Box<dyn Read + Send>),
            child
                .stdout
                .take()
                .map(|s| Box::new(s) as Box<dyn Read + Send>),
        ]
        .into_iter()
        .flatten()
        .collect();
        for stream in streams {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    if let Some(i) = line.find("/dev/pts/") {
                        let path: String = line[i..]
                            .chars()
                            .take_while(|c| !c.is_whitespace() && *c != ')')
                            .collect();
                        let _ = tx.send(path);
                    }
                }
            });
        }
        let mut board = Self {
            child,
            pty: String::new(),
        };
        match rx.recv_timeout(Duration::from_secs(20)) {
            Ok(pty) => board.pty = pty,
            Err(_) => {
                let status = board.child.try_wait().ok().flatten();
                return Err(io(
                    elf,
                    format!("QEMU named no pty within 20 s (exit status {status:?})"),
                ));
            }
        }
        Ok(board)
    }

    /// The pty of the board's UART.
    pub fn pty(&self) -> &str {
        &self.pty
    }
}

impl Drop for QemuBoard {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A freshly booted QEMU board and the serial link to it.
pub struct QemuLink {
    link: SerialLink,
    // Dropped after the link: the pty closes before QEMU is killed.
    _board: QemuBoard,
}

impl QemuLink {
    /// Boots `elf` and connects to it (waiting up to 20 s for a pong).
    pub fn boot(elf: &Path) -> Result<Self, SimError> {
        let board = QemuBoard::boot(elf)?;
        let link = SerialLink::open(board.pty(), 115_200, Duration::from_secs(20))?;
        Ok(Self {
            link,
            _board: board,
        })
    }
}

impl Link for QemuLink {
    fn exchange(&mut self, cmd: &Command, now_us: u32) -> Result<Reply, SimError> {
        self.link.exchange(cmd, now_us)
    }

    /// The largest watchdog the firmware accepts (10 s). The emulated SysTick follows the
    /// host's wall clock, not the lab's ticks, so a host that stalls between two exchanges
    /// for more than the lab's usual 1 s trips the watchdog and the firmware holds its
    /// pressures: a loaded CI machine did once (`tests/pil.rs`, tick 3473 of 4000), where the
    /// in-process twin, on the lab's clock, went on.
    fn link_timeout_us(&self) -> u32 {
        10_000_000
    }

    fn exchange_all(
        &mut self,
        cmds: &[Command],
        now_us: u32,
        replies: &mut Vec<Reply>,
    ) -> Result<(), SimError> {
        self.link.exchange_all(cmds, now_us, replies)
    }
}
