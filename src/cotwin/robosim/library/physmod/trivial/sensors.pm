// Sensors of RoboTool's trivial formulation, as cotwin reads them.
package physmod::trivial::sensors

import physmod::math::*

sensor TrivialSensor {
	input SignalIn: real
	output MeasurementOut: real
	equation MeasurementOut == SignalIn
}

// a rotary encoder: the angle and angular rate of the joint it is mounted on
sensor JointEncoder {
	input ThetaIn: real
	input DThetaIn: real
	output AngleOut: real
	output VelocityOut: real
	equation AngleOut == ThetaIn
	equation VelocityOut == DThetaIn
}

datatype LaserScan {
	angle_min: real
	angle_max: real
	angle_increment: real
	time_increment: real
	scan_time: real
	range_min: real
	range_max: real
	ranges: Seq(real)
	intensities: Seq(real)
}

// indicator of z in [lower, upper]
function ind(z: real, lower: real, upper: real): real {
	precondition lower <= upper
	postcondition result == if z >= lower /\ z <= upper then 1 else 0 end
}

// a range finder with the beam model of Thrun et al. (hit, short, max and random readings);
// cotwin's simulator casts its beams (cotwin.pmodel.simulator); the `scan` record is not filled
sensor Lidar {
	const PI: real = 3.141592653589793
	input trueDistance: real, measuredDistance: real, range_max: real
	input w_hit: real, w_short: real, w_max: real, w_rand: real
	input sigma_hit: real, lambda_short: real
	output scan: LaserScan
	output measurement: real
	local p_hit: real, p_short: real, p_max: real, p_rand: real, eta_short: real, N: real
	equation w_hit + w_short + w_max + w_rand == 1
	equation N == exp(-0.5 * ((measuredDistance - trueDistance) / sigma_hit)^2) / sqrt(2 * PI * sigma_hit^2)
	equation p_hit == ind(measuredDistance, 0, range_max) * N / integral(N, 0, range_max)
	equation eta_short == 1 / (1 - exp(-lambda_short * trueDistance))
	equation p_short == ind(measuredDistance, 0, trueDistance) * eta_short * lambda_short * exp(-lambda_short * measuredDistance)
	equation p_max == ind(measuredDistance, range_max, range_max)
	equation p_rand == ind(measuredDistance, 0, range_max) / range_max
	equation measurement == w_hit * p_hit + w_short * p_short + w_max * p_max + w_rand * p_rand
	equation scan.range_max == range_max
	equation scan.ranges == <measuredDistance>
}

// angular and linear rates of the body it is mounted on
sensor IMU {
	input angularRateAV: real
	input angularRateLV: real
	output currentLV: real
	output currentAV: real
	equation currentLV == angularRateLV
	equation currentAV == angularRateAV
}
