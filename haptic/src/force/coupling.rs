//! A shared tool: one tool body held by several devices through virtual spring-dampers, so
//! the tool moves with the users' combined motion and each user feels the others
//! (Newton's third law: the forces on the devices and on the tool sum to zero).

use glam::DVec3;

/// The shared tool's rigid body (translation only).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ToolBody {
    /// Position, world.
    pub position: DVec3,
    /// Velocity, world units per second.
    pub velocity: DVec3,
    /// Virtual mass, kilograms (> 0).
    pub mass_kg: f64,
}

/// The virtual coupling between a device tip and the tool.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coupling {
    /// Spring stiffness, newtons per world unit.
    pub stiffness: f64,
    /// Damping, newton-seconds per world unit.
    pub damping: f64,
}

/// One device holding the tool: its tip mapped into the shared world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grip {
    /// Tip position, world.
    pub position: DVec3,
    /// Tip velocity, world units per second.
    pub velocity: DVec3,
}

/// Computes the coupling force on each grip (written to `forces_on_grips`), advances the tool
/// by `dt_secs` under the opposite forces plus `external_force`, and returns the coupling force
/// on the tool. `forces_on_grips` must be as long as `grips`.
pub fn step_shared_tool(
    tool: &mut ToolBody,
    coupling: &Coupling,
    grips: &[Grip],
    external_force: DVec3,
    forces_on_grips: &mut [DVec3],
    dt_secs: f64,
) -> DVec3 {
    assert_eq!(
        grips.len(),
        forces_on_grips.len(),
        "one force slot per grip"
    );
    assert!(tool.mass_kg > 0.0, "tool mass must be positive");
    let mut on_tool = DVec3::ZERO;
    for (grip, force) in grips.iter().zip(forces_on_grips.iter_mut()) {
        *force = coupling.stiffness * (tool.position - grip.position)
            + coupling.damping * (tool.velocity - grip.velocity);
        on_tool -= *force;
    }
    tool.velocity += (on_tool + external_force) / tool.mass_kg * dt_secs;
    tool.position += tool.velocity * dt_secs;
    on_tool
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_users_feel_each_other_and_forces_balance() {
        let mut tool = ToolBody {
            position: DVec3::ZERO,
            velocity: DVec3::ZERO,
            mass_kg: 0.05,
        };
        let coupling = Coupling {
            stiffness: 200.0,
            damping: 3.0,
        };
        let grips = [
            Grip {
                position: DVec3::new(-0.01, 0.0, 0.0),
                velocity: DVec3::ZERO,
            },
            Grip {
                position: DVec3::new(0.03, 0.02, 0.0),
                velocity: DVec3::ZERO,
            },
        ];
        let mut forces = [DVec3::ZERO; 2];
        for _ in 0..3000 {
            let on_tool = step_shared_tool(
                &mut tool,
                &coupling,
                &grips,
                DVec3::ZERO,
                &mut forces,
                0.001,
            );
            // Newton's third law, every tick.
            assert!((on_tool + forces[0] + forces[1]).length() < 1e-12);
        }
        // The tool settles between the users; each feels the other pull with equal force.
        assert!(
            (tool.position - DVec3::new(0.01, 0.01, 0.0)).length() < 1e-6,
            "{tool:?}"
        );
        assert!((forces[0] + forces[1]).length() < 1e-6);
        assert!(forces[0].x > 3.9 && forces[1].x < -3.9, "{forces:?}");
    }
}
