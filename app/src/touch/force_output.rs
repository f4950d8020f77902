//! Where the live servo's force goes besides the screen: a HID force-feedback device
//! (through hidapi; [`haptic::device::hid::PidForce`], which renders the force's x component on
//! its axis), chosen while touching and unplugged without harm.
//!
//! The servo's device ([`super::live::ShownForce`]) holds an [`OutputSlot`]; the window holds
//! the [`ForceOutput`] that feeds it. A device opened on the window's thread is handed to the
//! servo through the haptic crate's lock-free hand-off, and a device the servo drops (a write
//! failed: it was unplugged) goes back the same way to be closed here, so the servo never
//! waits, allocates or frees. A device that cannot be opened is an error in words, with the
//! udev rule to add when the system refuses access. Listing and opening devices is IO, so the
//! window does both on a thread of its own ([`ForceOutput::start_open`], [`list_in_background`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use glam::DVec3;
use haptic::device::HapticDevice as _;
use haptic::device::hid::{self, HidDeviceInfo, OpenError, PidForce};
use haptic::handoff::{self, Publisher, Receiver};

/// A udev rule that lets the user's session open a HID force-feedback device.
pub const UDEV_RULE: &str =
    r#"KERNEL=="hidraw*", SUBSYSTEM=="hidraw", TAG+="uaccess", MODE="0660""#;

/// What the servo writes its force to: a device, or none.
pub enum Output {
    /// The force is shown only.
    Shown,
    /// A HID PID device renders it.
    Pid(PidForce),
}

/// Counters both ends read.
#[derive(Default)]
struct Counters {
    /// Forces written to the device.
    n_writes: AtomicU64,
    /// Set by the servo when a write failed and it let the device go.
    lost: AtomicBool,
}

/// The servo's end: the current output, and the hand-off it comes by.
pub struct OutputSlot {
    incoming: Receiver<Output>,
    current: Option<Box<Output>>,
    /// Values waiting for room on the hand-off's return ring.
    retiring: Option<Box<Output>>,
    counters: Arc<Counters>,
}

impl OutputSlot {
    /// Writes `force_newtons` to the device, if one is chosen. Never fails: a failed write
    /// drops the device (it goes back to the window to be closed) and the force is shown only.
    /// No allocation, lock or wait.
    pub fn write(&mut self, force_newtons: DVec3) {
        if let Some(old) = self.retiring.take() {
            self.retiring = self.incoming.retire(old).err();
        }
        if self.retiring.is_none()
            && let Some(next) = self.incoming.take()
            && let Some(old) = self.current.replace(next)
        {
            self.retiring = self.incoming.retire(old).err();
        }
        let Some(Output::Pid(device)) = self.current.as_deref_mut() else {
            return;
        };
        if device.set_force(force_newtons).is_ok() {
            self.counters.n_writes.fetch_add(1, Ordering::Relaxed);
            return;
        }
        self.counters.lost.store(true, Ordering::Relaxed);
        if self.retiring.is_none()
            && let Some(old) = self.current.take()
        {
            self.retiring = self.incoming.retire(old).err();
        }
    }
}

/// The window's end: opens, swaps and closes the device.
pub struct ForceOutput {
    outgoing: Publisher<Output>,
    counters: Arc<Counters>,
    chosen: Option<HidDeviceInfo>,
    force_newtons_max: f64,
}

/// A connected pair: the window's end and the servo's, for a device model rendering up to
/// `force_newtons_max` (the device's full scale).
pub fn channel(force_newtons_max: f64) -> (ForceOutput, OutputSlot) {
    let (outgoing, incoming) = handoff::channel();
    let counters = Arc::new(Counters::default());
    (
        ForceOutput {
            outgoing,
            counters: Arc::clone(&counters),
            chosen: None,
            force_newtons_max,
        },
        OutputSlot {
            incoming,
            current: None,
            retiring: None,
            counters,
        },
    )
}

/// The connected HID devices that may render force, or why none can be listed.
pub fn devices() -> Result<Vec<HidDeviceInfo>, String> {
    hid::force_feedback_devices().map_err(|e| open_error_text(&e))
}

/// Words for why a force-feedback device could not be used, with what to do.
pub fn open_error_text(e: &OpenError) -> String {
    match e {
        OpenError::NotFound => "that force-feedback device is not connected: plug it in and \
                                choose it again"
            .into(),
        OpenError::Api(_) | OpenError::Open(_) => cannot_open_text(&e.to_string()),
        OpenError::Effect(why) => format!(
            "the device refused the force effect ({why}): it may not support HID PID constant \
             force"
        ),
    }
}

/// A device being opened on its own thread (see [`ForceOutput::start_open`]).
pub struct Opening(std::sync::mpsc::Receiver<Result<(PidForce, HidDeviceInfo), String>>);

/// Lists the force-feedback devices on a thread of its own; the answer comes on the receiver.
pub fn list_in_background() -> std::sync::mpsc::Receiver<Result<Vec<HidDeviceInfo>, String>> {
    let (tx, rx) = std::sync::mpsc::channel();
    let spawned = std::thread::Builder::new()
        .name("sculpt-hid-list".into())
        .spawn(move || {
            let _ = tx.send(devices());
        });
    if let Err(e) = spawned {
        log::warn!("cannot list HID devices: {e}");
    }
    rx
}

/// Opens `vendor_id:product_id` for a device rendering up to `force_newtons_max` (blocking:
/// hidapi's enumeration and the effect's feature reports).
fn open_blocking(
    vendor_id: u16,
    product_id: u16,
    force_newtons_max: f64,
) -> Result<(PidForce, HidDeviceInfo), String> {
    let device = PidForce::open(vendor_id, product_id, force_newtons_max)
        .map_err(|e| open_error_text(&e))?;
    let name = hid::force_feedback_devices()
        .ok()
        .and_then(|list| {
            list.into_iter()
                .find(|d| (d.vendor_id, d.product_id) == (vendor_id, product_id))
        })
        .map_or_else(String::new, |d| d.name);
    let info = HidDeviceInfo {
        vendor_id,
        product_id,
        name,
    };
    Ok((device, info))
}

impl ForceOutput {
    /// Starts opening `vendor_id:product_id` on a thread of its own (hidapi's enumeration and
    /// the effect's feature reports are IO); pass the result to [`ForceOutput::finish_open`]
    /// until it answers. On an error the force stays where it was going.
    pub fn start_open(&self, vendor_id: u16, product_id: u16) -> Opening {
        let (tx, rx) = std::sync::mpsc::channel();
        let max = self.force_newtons_max;
        let spawned = std::thread::Builder::new()
            .name("sculpt-hid-open".into())
            .spawn(move || {
                let _ = tx.send(open_blocking(vendor_id, product_id, max));
            });
        if let Err(e) = spawned {
            let (tx, rx) = std::sync::mpsc::channel();
            let _ = tx.send(Err(format!("cannot start opening the device: {e}")));
            return Opening(rx);
        }
        Opening(rx)
    }

    /// The outcome of `opening` once it came (then the device takes the force from the
    /// servo's next tick), `None` while it is still opening.
    pub fn finish_open(&mut self, opening: &Opening) -> Option<Result<(), String>> {
        let outcome = match opening.0.try_recv() {
            Ok(outcome) => outcome,
            Err(std::sync::mpsc::TryRecvError::Empty) => return None,
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                Err("the device could not be opened (its thread stopped)".into())
            }
        };
        Some(outcome.map(|(device, info)| self.use_device(device, info)))
    }

    fn use_device(&mut self, device: PidForce, info: HidDeviceInfo) {
        self.counters.lost.store(false, Ordering::Relaxed);
        self.outgoing.publish(Box::new(Output::Pid(device)));
        self.chosen = Some(info);
    }

    /// Shows the force only (the device is closed once the servo hands it back).
    pub fn close(&mut self) {
        self.outgoing.publish(Box::new(Output::Shown));
        self.chosen = None;
    }

    /// Closes what the servo handed back (call every frame).
    pub fn collect(&self) {
        self.outgoing.collect_retired();
    }

    /// The chosen device, while it works.
    pub fn device(&self) -> Option<&HidDeviceInfo> {
        self.chosen
            .as_ref()
            .filter(|_| !self.counters.lost.load(Ordering::Relaxed))
    }

    /// Forces written to the device so far.
    pub fn n_writes(&self) -> u64 {
        self.counters.n_writes.load(Ordering::Relaxed)
    }

    /// Where the force goes, in a line for the window.
    pub fn status(&self) -> String {
        match (&self.chosen, self.counters.lost.load(Ordering::Relaxed)) {
            (None, _) => "force shown only (no force-feedback device chosen)".into(),
            (Some(d), true) => format!(
                "{} stopped answering (unplugged?): the force is shown only; plug it in and \
                 choose it again",
                label(d)
            ),
            (Some(d), false) => format!("force on {} (its axis renders x)", label(d)),
        }
    }
}

/// Words for a device the system would not open (`detail`: its reason).
fn cannot_open_text(detail: &str) -> String {
    format!(
        "the force-feedback device cannot be opened ({detail}): add the udev rule \
         `{UDEV_RULE}` to /etc/udev/rules.d/70-sculpt-force-feedback.rules, run `sudo udevadm \
         control --reload && sudo udevadm trigger`, plug it in again and choose it again"
    )
}

/// A device in words: its name and ids.
pub fn label(d: &HidDeviceInfo) -> String {
    let name = if d.name.is_empty() {
        "HID device"
    } else {
        &d.name
    };
    format!("{name} ({:04x}:{:04x})", d.vendor_id, d.product_id)
}

/// Reads `VID:PID` in hexadecimal (`1234:f00d`).
pub fn parse_ids(text: &str) -> Option<(u16, u16)> {
    let (v, p) = text.trim().split_once(':')?;
    Some((
        u16::from_str_radix(v.trim(), 16).ok()?,
        u16::from_str_radix(p.trim(), 16).ok()?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Set in the child process the fake device runs.
    const CHILD_ENV: &str = "SCULPT_FAKE_PID_CHILD";

    /// The live servo on the demo watermelon, its force sent to the fake HID PID device
    /// (haptic's FUSE fake, vendor 1234, product f00d): the rind's push along -x arrives as
    /// constant-force reports, and closing the output hands the device back. This test runs
    /// itself again under the fake, which needs root and FUSE; elsewhere it says why it
    /// skipped.
    #[test]
    fn the_live_servos_force_reaches_a_hid_force_feedback_device() {
        use crate::touch::DeviceModel;
        use crate::touch::live::LiveTouch;
        if std::env::var(CHILD_ENV).is_ok() {
            let (engine, dir) = crate::touch::live::tests::watermelon_engine("ff");
            let wait = |what: &str, done: &dyn Fn() -> bool| {
                let deadline = crate::clock::now().instant + std::time::Duration::from_secs(20);
                while !done() {
                    assert!(crate::clock::now().instant < deadline, "timed out: {what}");
                    std::thread::sleep(std::time::Duration::from_millis(5));
                }
            };
            let list = devices().unwrap();
            assert!(
                list.iter()
                    .any(|d| (d.vendor_id, d.product_id) == (0x1234, 0xf00d)),
                "{list:?}"
            );
            let mut live =
                LiveTouch::start(std::sync::Arc::clone(engine.view()), DeviceModel::Falcon)
                    .unwrap();
            // As the window opens it: on a thread of its own.
            let opening = live.force_output_ref().start_open(0x1234, 0xf00d);
            let opened = loop {
                if let Some(outcome) = live.force_output().finish_open(&opening) {
                    break outcome;
                }
                std::thread::sleep(std::time::Duration::from_millis(5));
            };
            opened.unwrap();
            // Beside the melon on its -x side, then 0.02 into its rind: pushed along -x.
            live.move_to_world(DVec3::new(-1.4, 0.2, -0.2));
            wait("beside", &|| live.stats().top_id.is_none());
            let x = -(0.98f64 * 0.98 - 0.08).sqrt();
            live.move_to_world(DVec3::new(x, 0.2, -0.2));
            wait("the rind's push", &|| live.stats().force_newtons.x < -1.0);
            wait("writes", &|| live.force_output_ref().n_writes() > 200);
            let status = live.force_output_ref().status();
            println!("CHILD status: {status}");
            // Closed: the servo takes the change at its next tick and writes no more.
            live.force_output().close();
            std::thread::sleep(std::time::Duration::from_millis(50));
            let writes = live.force_output_ref().n_writes();
            std::thread::sleep(std::time::Duration::from_millis(50));
            live.force_output_ref().collect();
            println!(
                "CHILD writes after close: {}",
                live.force_output_ref().n_writes() - writes
            );
            live.stop();
            engine.shutdown();
            let _ = std::fs::remove_dir_all(&dir);
            return;
        }
        let fake = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../haptic/tests/fake-hid/run.sh");
        let exe = std::env::current_exe().unwrap();
        let out = std::process::Command::new(fake)
            .env("FAKE_HID_KIND", "pid")
            .env(CHILD_ENV, "1")
            .arg(exe)
            .args([
                "--exact",
                "touch::force_output::tests::the_live_servos_force_reaches_a_hid_force_feedback_device",
                "--nocapture",
                "--test-threads=1",
            ])
            .stdin(std::process::Stdio::null())
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        if out.status.code() == Some(77) {
            eprintln!("skipped the fake force-feedback device: {stdout}");
            return;
        }
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{stdout}\n{stderr}");
        assert!(
            stdout.contains("CHILD status: force on Fake HID PID joystick (1234:f00d)"),
            "{stdout}"
        );
        assert!(stdout.contains("CHILD writes after close: 0"), "{stdout}");
        let log = stdout.split_once("--- device log:").map_or("", |(_, l)| l);
        assert!(log.contains("feature set: 0b010000"), "{log}");
        let forces: Vec<&str> = log
            .lines()
            .filter_map(|l| l.trim().strip_prefix("output report: 0507"))
            .collect();
        // A negative magnitude (along -x) has the top bit of its high byte set.
        let negative = |f: &str| {
            u8::from_str_radix(f.get(2..4)?, 16)
                .ok()
                .map(|h| h & 0x80 != 0)
        };
        assert!(
            forces.iter().filter(|f| negative(f) == Some(true)).count() > 100,
            "the rind pushes along -x: {} reports",
            forces.len()
        );
    }

    #[test]
    fn ids_read_in_hex_and_errors_say_what_to_do() {
        assert_eq!(parse_ids("1234:f00d"), Some((0x1234, 0xf00d)));
        assert_eq!(parse_ids(" 046D : C626 "), Some((0x046d, 0xc626)));
        for bad in ["", "1234", "12345:1", "x:1", "1:2:3"] {
            assert_eq!(parse_ids(bad), None, "{bad}");
        }
        assert!(open_error_text(&OpenError::NotFound).contains("plug it in"));
        let denied = cannot_open_text("Permission denied");
        assert!(
            denied.contains(UDEV_RULE) && denied.contains("Permission denied"),
            "{denied}"
        );
    }

    #[test]
    fn with_no_device_the_slot_writes_nothing_and_says_so() {
        let (mut output, mut slot) = channel(8.0);
        slot.write(DVec3::X);
        assert_eq!(output.n_writes(), 0);
        assert!(output.status().contains("shown only"));
        let opening = output.start_open(0xdead, 0xbeef);
        let outcome = loop {
            if let Some(outcome) = output.finish_open(&opening) {
                break outcome;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        };
        assert!(outcome.is_err(), "no such device");
        assert!(output.device().is_none());
        output.close();
        slot.write(DVec3::X);
        output.collect();
        assert_eq!(output.n_writes(), 0);
    }
}
