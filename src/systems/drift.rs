//! Plate drift (paper §3, Driftworld §3.6): each plate turns about its Euler pole by ω·δt.

use bevy_ecs::prelude::*;
use glam::DQuat;

use crate::components::{PlateFrame, PlateMotion};
use crate::resources::params::Params;

/// Turns every plate by one time step.
pub fn drift_plates(params: Res<Params>, mut plates: Query<(&PlateMotion, &mut PlateFrame)>) {
    let dt = params.time.time_step_my;
    for (motion, mut frame) in &mut plates {
        let turn = DQuat::from_axis_angle(motion.euler_pole, motion.angular_speed_rad_per_my * dt);
        frame.world_from_plate = (turn * frame.world_from_plate).normalize();
    }
}
