//! A 3D mouse (3Dconnexion SpaceMouse, through hidapi) as the touch tool's input: a rate
//! controller. Pushing the cap moves the tool at a speed proportional to the push, letting go
//! leaves it where it is, which is what touching needs (a position controller would spring
//! the tool back to the middle the moment the hand relaxes).
//!
//! The driver runs on a thread of its own (`sculpt-3d-mouse`), never on the servo's: it reads
//! the device, integrates the speed into the live touch's lock-free mouse device (the servo
//! samples that at 1 kHz as for the pointer), and mirrors the cap's first button into the
//! device button (touch-sculpting). Plugging and unplugging are expected: without a device it
//! looks again every [`SEARCH_EVERY_MILLIS`], a device that stops answering is dropped and
//! looked for again, and [`SpaceMouseDriver::status`] says what is happening in words a
//! person can act on (which udev rule to add when the device is there but may not be read).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use glam::DVec3;
use haptic::device::hid::{AXIS_FULL_SCALE, OpenError, SpaceMouse};
use haptic::device::mouse::MouseHandle;

/// How often the driver looks for a device while it has none.
pub const SEARCH_EVERY_MILLIS: u64 = 1_000;
/// How long one read waits for a report.
const READ_WAIT_MILLIS: i32 = 10;
/// Tool speed at full deflection, device metres per second (a Falcon-class workspace is
/// 0.1 m across: about a second from side to side).
pub const FULL_SPEED_METRES_PER_SEC: f64 = 0.1;
/// Deflections below this fraction of full scale are rest (the cap never reads exactly 0).
pub const DEADZONE: f64 = 0.05;
/// Longest step integrated at once, seconds (a stalled thread must not jump the tool).
const MAX_STEP_SECS: f64 = 0.05;

/// The rule that lets a logged-in user read 3Dconnexion devices, for the permission message.
pub const UDEV_RULE: &str = "KERNEL==\"hidraw*\", ATTRS{idVendor}==\"256f\", MODE=\"0660\", \
                             TAG+=\"uaccess\"";

/// What the driver is doing.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SpaceMouseStatus {
    /// A device is open and moves the tool.
    Connected,
    /// No usable device; the text says why and what to do. The driver keeps looking.
    Searching(String),
}

impl SpaceMouseStatus {
    /// The status in a line for the window.
    pub fn text(&self) -> String {
        match self {
            Self::Connected => "3D mouse connected: push the cap to move the tool".into(),
            Self::Searching(why) => why.clone(),
        }
    }
}

/// Words for why no device could be opened.
pub fn open_error_text(e: &OpenError) -> String {
    match e {
        OpenError::NotFound => "no 3D mouse found: plug one in (still looking)".into(),
        OpenError::Api(_) | OpenError::Open(_) => cannot_read_text(&e.to_string()),
        OpenError::Effect(_) => e.to_string(),
    }
}

/// Words for a device that is there but may not be read (`detail`: the system's reason).
fn cannot_read_text(detail: &str) -> String {
    format!(
        "a 3D mouse may be there but cannot be read ({detail}): add the udev rule \
         `{UDEV_RULE}` to /etc/udev/rules.d/70-sculpt-3d-mouse.rules, run \
         `sudo udevadm control --reload && sudo udevadm trigger`, and plug it in again \
         (still looking)"
    )
}

/// The tool's move for a deflection held `dt_secs`: each axis scaled to [-1, 1] by
/// [`AXIS_FULL_SCALE`], rest inside [`DEADZONE`], at most [`FULL_SPEED_METRES_PER_SEC`].
pub fn rate_step(translation: [i16; 3], dt_secs: f64) -> DVec3 {
    let dt = dt_secs.clamp(0.0, MAX_STEP_SECS);
    let axis = |a: i16| {
        let v = (f64::from(a) / AXIS_FULL_SCALE).clamp(-1.0, 1.0);
        if v.abs() < DEADZONE { 0.0 } else { v }
    };
    DVec3::new(
        axis(translation[0]),
        axis(translation[1]),
        axis(translation[2]),
    ) * FULL_SPEED_METRES_PER_SEC
        * dt
}

/// The running driver.
pub struct SpaceMouseDriver {
    status: Arc<Mutex<SpaceMouseStatus>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl SpaceMouseDriver {
    /// Starts driving `mouse` (the live touch's device) from the first 3D mouse found;
    /// `button` hears the cap's first button when it changes.
    pub fn spawn(
        mouse: MouseHandle,
        button: impl Fn(bool) + Send + 'static,
    ) -> std::io::Result<SpaceMouseDriver> {
        let status = Arc::new(Mutex::new(SpaceMouseStatus::Searching(
            "looking for a 3D mouse".into(),
        )));
        let stop = Arc::new(AtomicBool::new(false));
        let (status_in, stop_in) = (Arc::clone(&status), Arc::clone(&stop));
        let thread = std::thread::Builder::new()
            .name("sculpt-3d-mouse".into())
            .spawn(move || drive(&mouse, &button, &status_in, &stop_in))?;
        Ok(SpaceMouseDriver {
            status,
            stop,
            thread: Some(thread),
        })
    }

    /// What the driver is doing now.
    pub fn status(&self) -> SpaceMouseStatus {
        self.status
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Stops the thread (within one search interval) and closes the device.
    pub fn stop(mut self) {
        self.halt();
    }

    fn halt(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            log::error!("the 3D mouse thread panicked");
        }
    }
}

impl Drop for SpaceMouseDriver {
    fn drop(&mut self) {
        self.halt();
    }
}

fn drive(
    mouse: &MouseHandle,
    button: &dyn Fn(bool),
    status: &Mutex<SpaceMouseStatus>,
    stop: &AtomicBool,
) {
    let set = |s: SpaceMouseStatus| {
        let mut now = status.lock().unwrap_or_else(PoisonError::into_inner);
        if *now != s {
            log::info!("3D mouse: {}", s.text());
            *now = s;
        }
    };
    while !stop.load(Ordering::Relaxed) {
        let mut device = match SpaceMouse::open_first() {
            Ok(device) => device,
            Err(e) => {
                set(SpaceMouseStatus::Searching(open_error_text(&e)));
                sleep_unless_stopped(stop, SEARCH_EVERY_MILLIS);
                continue;
            }
        };
        set(SpaceMouseStatus::Connected);
        let mut last = crate::clock::now().instant;
        let mut pressed = false;
        while !stop.load(Ordering::Relaxed) {
            if device.poll(READ_WAIT_MILLIS).is_err() {
                set(SpaceMouseStatus::Searching(
                    "the 3D mouse was unplugged: plug it in again (still looking)".into(),
                ));
                break;
            }
            let now = crate::clock::now().instant;
            let state = device.state();
            mouse.move_by_metres(rate_step(state.translation, (now - last).as_secs_f64()));
            last = now;
            let down = state.buttons & 1 != 0;
            if down != pressed {
                pressed = down;
                button(down);
            }
        }
    }
}

/// Sleeps `millis` in short naps, returning early once `stop` is set.
fn sleep_unless_stopped(stop: &AtomicBool, millis: u64) {
    let mut left = millis;
    while left > 0 && !stop.load(Ordering::Relaxed) {
        let nap = left.min(50);
        std::thread::sleep(Duration::from_millis(nap));
        left -= nap;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_push_moves_the_tool_at_a_speed_proportional_to_it_and_rest_holds_it() {
        let full = AXIS_FULL_SCALE as i16;
        let step = rate_step([full, -full / 2, 0], 0.01);
        assert!(
            (step - DVec3::new(0.001, -0.0005, 0.0)).length() < 1e-12,
            "{step}"
        );
        // Inside the deadzone, and past full scale.
        assert_eq!(rate_step([10, -10, 17], 0.01), DVec3::ZERO);
        let beyond = rate_step([i16::MAX, 0, 0], 0.01);
        assert!((beyond.x - 0.001).abs() < 1e-12, "{beyond}");
        // A stalled thread does not jump the tool; time going back does not move it.
        let stalled = rate_step([full, 0, 0], 3.0);
        assert!((stalled.x - FULL_SPEED_METRES_PER_SEC * MAX_STEP_SECS).abs() < 1e-12);
        assert_eq!(rate_step([full, 0, 0], -1.0), DVec3::ZERO);
    }

    #[test]
    fn without_a_device_the_status_says_what_to_do() {
        assert!(open_error_text(&OpenError::NotFound).contains("plug one in"));
        let text = cannot_read_text("cannot open /dev/hidraw3: Permission denied");
        assert!(
            text.contains(UDEV_RULE) && text.contains("udevadm"),
            "{text}"
        );
        assert!(text.contains("Permission denied"), "{text}");
    }
}
