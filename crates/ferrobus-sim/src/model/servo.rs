//! A servo drive in speed mode: with the servo on, the motor speed follows the speed command
//! with the acceleration time, and the position integrates the speed.
//!
//! Names are the SDP profile's: `servo-on`, `speed-command` (r/min), `acceleration-time` (ms
//! from 0 to the rated speed); outputs `motor-speed`, `position` (encoder pulses), `torque`
//! (% of rated), `servo-status`. The SDP manual documents none of these beyond the example
//! write to 0112H; see the profile's [U] notes.

use std::time::Duration;

use super::Model;
use crate::memory::Memory;

/// The servo.
#[derive(Debug)]
pub struct Servo {
    rated_speed: f64,
    pulses_per_revolution: f64,
    /// r/min, signed.
    speed: f64,
    /// Encoder pulses.
    position: f64,
    torque: f64,
}

impl Servo {
    /// A servo at rest, servo off.
    pub fn new(rated_speed: u32, pulses_per_revolution: u32) -> Self {
        Servo {
            rated_speed: f64::from(rated_speed.max(1)),
            pulses_per_revolution: f64::from(pulses_per_revolution),
            speed: 0.0,
            position: 0.0,
            torque: 0.0,
        }
    }
}

impl Model for Servo {
    fn advance(&mut self, memory: &mut Memory, dt: Duration) {
        let on = memory.get("servo-on") != 0;
        let command = if on { memory.get("speed-command") as f64 } else { 0.0 };
        let ramp_ms = (memory.get("acceleration-time") as f64).max(1.0);
        let slope = self.rated_speed / (ramp_ms / 1000.0);
        let dt = dt.as_secs_f64();
        let before = self.speed;
        let gap = command - self.speed;
        let step = slope * dt;
        // Integrate the position over the step with the mean speed.
        self.speed = if gap.abs() <= step { command } else { self.speed + step * gap.signum() };
        self.position += before.midpoint(self.speed) / 60.0 * self.pulses_per_revolution * dt;
        let accelerating = (self.speed - before).abs() > f64::EPSILON;
        self.torque = if !on {
            0.0
        } else if accelerating {
            100.0 * (self.speed - before).signum()
        } else {
            5.0 * self.speed.signum()
        };
        memory.set("motor-speed", self.speed.round() as i64);
        // The position register is a 32-bit counter that wraps.
        memory.set("position", i64::from((self.position.round() as i64) as i32));
        memory.set("torque", self.torque.round() as i64);
        memory.set(
            "servo-status",
            if !on {
                0
            } else if self.speed != 0.0 {
                2
            } else {
                1
            },
        );
    }

    fn summary(&self, memory: &Memory) -> String {
        format!(
            "servo {}, {:.0} r/min of {} r/min, position {}",
            if memory.get("servo-on") != 0 { "on" } else { "off" },
            self.speed,
            memory.get("speed-command"),
            memory.get("position")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::Profile;

    #[test]
    fn the_motor_follows_the_speed_command_only_with_the_servo_on() {
        let mut memory = Memory::new(&Profile::load("sdp-servo").unwrap());
        let mut servo = Servo::new(3000, 131_072);
        memory.set("speed-command", 3000);
        memory.set("acceleration-time", 100);
        servo.advance(&mut memory, Duration::from_millis(500));
        assert_eq!(memory.get("motor-speed"), 0, "servo off");
        memory.set("servo-on", 1);
        servo.advance(&mut memory, Duration::from_millis(50));
        assert_eq!(memory.get("motor-speed"), 1500);
        assert_eq!(memory.get("torque"), 100);
        servo.advance(&mut memory, Duration::from_millis(50));
        servo.advance(&mut memory, Duration::from_secs(1));
        assert_eq!(memory.get("motor-speed"), 3000);
        assert_eq!(memory.get("servo-status"), 2);
        // 0.1 s ramping to 3000 r/min (2.5 revolutions), then 1 s at speed (50 revolutions).
        assert_eq!(memory.get("position"), (52.5 * 131_072.0) as i64);
    }
}
