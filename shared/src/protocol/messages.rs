//! Message types of the host <-> firmware protocol.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::params::{ManipulatorParams, OcmParams};

/// Most segments the firmware supports.
pub const MAX_SEGMENTS: usize = 3;
/// Most actuators (three columns per segment).
pub const MAX_ACTUATORS: usize = 3 * MAX_SEGMENTS;
/// Largest LUT upload chunk in bytes.
pub const LUT_CHUNK: usize = 128;
/// Most calibration points per actuator in one [`Calibration`].
pub const MAX_CAL_POINTS: usize = 24;

/// A command from the host, tagged with a sequence number the reply echoes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Command {
    /// Chosen by the host; echoed in the [`Reply`].
    pub seq: u16,
    /// What to do.
    pub body: CommandBody,
}

/// All commands the firmware understands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum CommandBody {
    /// Liveness check; answered by [`ReplyBody::Pong`].
    Ping {
        /// Echoed back.
        nonce: u32,
    },
    /// Ask for [`Info`].
    GetInfo,
    /// Start a LUT upload; drops the loaded LUT and stops control.
    LutBegin {
        /// Total image length in bytes.
        total_len: u32,
        /// CRC-32/ISO-HDLC of the whole image.
        crc32: u32,
    },
    /// The next piece of the image; must start where the previous ended.
    LutChunk {
        /// Byte offset of `data` in the image.
        offset: u32,
        /// Up to [`LUT_CHUNK`] bytes.
        data: Vec<u8, LUT_CHUNK>,
    },
    /// Finish the upload: check length and CRC, then validate the image.
    LutCommit,
    /// Switch the operating mode.
    SetMode(Mode),
    /// Set the PD(+I) gains of closed-loop control.
    SetGains(Gains),
    /// Set pressure limits and slew rate.
    SetLimits(Limits),
    /// Set watchdog and safe-state behaviour.
    SetSafety(SafetyConfig),
    /// Set the manipulator and OCM parameters the kinematics use.
    SetGeometry(Geometry),
    /// Set the target configuration or tip position and the expected load.
    SetTarget(Target),
    /// Fit one actuator's Hall map from calibration points.
    Calibrate(Calibration),
    /// One sample of raw sensor data; runs one control tick.
    SensorFrame(SensorFrame),
    /// Clear latched faults (the mode stays Safe until set again).
    ClearFaults,
}

/// Operating modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Mode {
    /// Outputs vented, no control.
    Idle,
    /// Pressures from the inverse model only.
    OpenLoop,
    /// Inverse-model feed-forward plus PD feedback on the configuration.
    ClosedLoop,
    /// Entered on faults or link loss; outputs held or vented.
    Safe,
}

/// Feedback gains in SI units, applied per actuator to the length error.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Gains {
    /// Proportional gain, pascal per metre of length error.
    pub kp_pa_per_m: f32,
    /// Derivative gain on the measured length rate, pascal per (metre per second).
    pub kd_pa_s_per_m: f32,
    /// Integral gain, pascal per (metre second); 0 gives pure PD.
    pub ki_pa_per_m_s: f32,
    /// Time constant of the derivative low-pass filter, seconds.
    pub derivative_filter_s: f32,
}

/// Output limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Limits {
    /// Lowest commanded gauge pressure, pascal.
    pub min_pa: f32,
    /// Highest commanded gauge pressure, pascal.
    pub max_pa: f32,
    /// Largest change of a command, pascal per second.
    pub slew_pa_per_s: f32,
}

/// What the outputs do in the safe state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum SafeAction {
    /// Keep the last commanded pressures.
    Hold,
    /// Command atmospheric pressure (0 Pa gauge, clamped into the limits).
    Vent,
}

/// Watchdog and fault handling.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SafetyConfig {
    /// Link silence that triggers the safe state, microseconds.
    pub link_timeout_us: u32,
    /// Safe-state output behaviour.
    pub action: SafeAction,
    /// Ticks a Hall code may stay frozen while the command moves before it
    /// counts as stuck.
    pub stuck_ticks: u16,
}

/// Manipulator description the firmware needs for kinematics.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Geometry {
    /// Manipulator layout (column radius, plate mass, OCMs per column, segments).
    pub manipulator: ManipulatorParams,
    /// OCM parameters; their hash must match the loaded LUT.
    pub ocm: OcmParams,
    /// Which way gravity acts along the backbone.
    pub mount: Mount,
}

/// Mounting of the manipulator base.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Mount {
    /// Base below, backbone up: weights compress the actuators.
    Upright,
    /// Base above, backbone down (App. B): weights stretch the actuators.
    Hanging,
}

/// A PCC configuration of one segment on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct SegmentConfig {
    /// Backbone arc length `S_c`, metres Q8.24.
    pub backbone_q24: i32,
    /// Bending angle `theta_c`, radians Q3.28.
    pub bend_q28: i32,
    /// Bending direction `phi_c` from actuator 1 towards actuator 2, radians Q3.28.
    pub direction_q28: i32,
}

/// What to reach.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum TargetKind {
    /// One configuration per segment, base segment first.
    Configuration(Vec<SegmentConfig, MAX_SEGMENTS>),
    /// Tip position in the base frame, metres Q8.24; all segments bend alike.
    TipPosition {
        /// x, metres Q8.24.
        x_q24: i32,
        /// y, metres Q8.24.
        y_q24: i32,
        /// z (along the unbent backbone), metres Q8.24.
        z_q24: i32,
    },
}

/// External load at the tip, in the base frame of the unbent manipulator.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Load {
    /// Payload mass hanging at the tip, kilograms (adds its weight).
    pub payload_kg: f32,
    /// Extra axial force along the backbone, newtons (positive stretches).
    pub force_z_n: f32,
    /// External moment about x, newton metres.
    pub moment_x_newton_m: f32,
    /// External moment about y, newton metres.
    pub moment_y_newton_m: f32,
}

/// A target with the load the feed-forward must compensate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Target {
    /// Configuration or tip position.
    pub kind: TargetKind,
    /// Expected external load.
    pub load: Load,
}

/// One calibration point: a raw Hall code and the true column length.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct CalPoint {
    /// ADS1115 code.
    pub code: i16,
    /// Reference length of the actuator column, metres Q8.24.
    pub length_q24: i32,
}

/// Calibration data for one actuator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Actuator index (segment * 3 + column).
    pub actuator: u8,
    /// Points; at least three.
    pub points: Vec<CalPoint, MAX_CAL_POINTS>,
}

/// One sample of the raw sensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorFrame {
    /// ADS1115 codes of the Hall sensors, one per actuator.
    pub hall_codes: Vec<i16, MAX_ACTUATORS>,
    /// IMU orientation of the tip plate (w, x, y, z), Q2.14.
    pub imu_quat_q14: [i16; 4],
    /// Measured chamber gauge pressures, one per actuator, pascal.
    pub pressures_pa: Vec<i32, MAX_ACTUATORS>,
}

/// A reply from the firmware.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reply {
    /// Sequence number of the command this answers (0 for unsolicited).
    pub seq: u16,
    /// The answer.
    pub body: ReplyBody,
}

/// All replies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ReplyBody {
    /// Answer to [`CommandBody::Ping`].
    Pong {
        /// The ping's nonce.
        nonce: u32,
    },
    /// Answer to [`CommandBody::GetInfo`].
    Info(Info),
    /// Command accepted.
    Ack,
    /// LUT chunk stored; bytes received so far.
    LutProgress {
        /// Bytes received.
        received: u32,
    },
    /// LUT committed and valid.
    LutLoaded {
        /// Parameter hash stored in the image.
        param_hash: u64,
        /// Image length in bytes.
        len: u32,
    },
    /// Calibration result.
    Calibrated(CalibrationReport),
    /// Result of a control tick.
    Telemetry(Telemetry),
    /// The command was rejected and changed nothing.
    Error(ProtocolError),
}

/// Static facts about the firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Info {
    /// [`crate::protocol::PROTOCOL_VERSION`] of the firmware.
    pub protocol_version: u16,
    /// Firmware crate version, major/minor/patch.
    pub firmware_version: [u8; 3],
    /// Bytes the LUT buffer holds.
    pub lut_capacity: u32,
    /// Whether a valid LUT is loaded.
    pub lut_loaded: bool,
    /// Segments configured.
    pub segments: u8,
    /// Control period, microseconds.
    pub control_period_us: u32,
    /// Current mode.
    pub mode: Mode,
}

/// Result of fitting one actuator's Hall map.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct CalibrationReport {
    /// Actuator index.
    pub actuator: u8,
    /// Fitted slope, metres per code, Q24.40.
    pub slope_q40: i64,
    /// Fitted length at code 0, metres Q8.24 (widened).
    pub offset_q24: i64,
    /// Coefficient of determination, Q1.15 (32768 = 1).
    pub r2_q15: u16,
    /// RMS residual of the kept points, metres Q8.24.
    pub rms_residual_q24: u32,
    /// Points kept in the fit.
    pub used: u8,
    /// Points rejected as outliers.
    pub rejected: u8,
}

/// Bit flags of latched faults.
pub mod fault {
    /// The link watchdog expired.
    pub const LINK_LOSS: u16 = 1 << 0;
    /// A Hall code is outside its calibrated range or saturated.
    pub const HALL_RANGE: u16 = 1 << 1;
    /// A Hall code stayed frozen while the command moved.
    pub const HALL_STUCK: u16 = 1 << 2;
    /// The IMU quaternion is far from unit length.
    pub const IMU_INVALID: u16 = 1 << 3;
    /// A measured chamber pressure is outside the plausible range.
    pub const PRESSURE_RANGE: u16 = 1 << 4;
    /// A sensor frame had the wrong number of channels.
    pub const SENSOR_SHAPE: u16 = 1 << 5;
    /// The kinematics could not be evaluated (outside the LUT domain).
    pub const MODEL: u16 = 1 << 6;
}

/// Telemetry after one control tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// Control ticks run since boot.
    pub tick: u32,
    /// Mode after the tick.
    pub mode: Mode,
    /// Latched [`fault`] flags.
    pub faults: u16,
    /// Estimated configuration per segment (zero when uncalibrated).
    pub estimate: Vec<SegmentConfig, MAX_SEGMENTS>,
    /// Estimated tip position (x, y, z), metres Q8.24.
    pub tip_q24: [i32; 3],
    /// Commanded gauge pressures, one per actuator, pascal Q24.8.
    pub commanded_pa_q8: Vec<i32, MAX_ACTUATORS>,
    /// Time the tick took, microseconds (board clock).
    pub loop_time_us: u32,
}

/// Why a command was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ProtocolError {
    /// The frame itself was bad.
    Frame(crate::protocol::FrameError),
    /// A LUT chunk or commit arrived without a matching begin.
    LutNotStarted,
    /// A LUT chunk did not start where the previous one ended.
    LutOutOfOrder {
        /// Offset the firmware expected.
        expected: u32,
        /// Offset received.
        got: u32,
    },
    /// The LUT image does not fit in the buffer, or a chunk runs past its end.
    LutTooLarge {
        /// Buffer capacity in bytes.
        capacity: u32,
    },
    /// Commit before all bytes arrived.
    LutIncomplete {
        /// Bytes received.
        received: u32,
        /// Bytes announced.
        total: u32,
    },
    /// The CRC over the uploaded bytes does not match the announced one.
    LutCrc,
    /// The image failed validation (format, version, internal CRC).
    LutInvalid,
    /// The image's parameter hash differs from the configured OCM parameters.
    LutParamMismatch,
    /// A LUT is loaded; the buffer is locked until reboot.
    LutLocked,
    /// The mode needs a valid LUT and none is loaded.
    NoLut,
    /// The mode needs a target and none is set.
    NoTarget,
    /// Closed loop needs every actuator calibrated.
    NotCalibrated,
    /// Active faults block leaving the safe state; clear them first.
    FaultsActive {
        /// The latched flags.
        faults: u16,
    },
    /// A numeric argument is out of range or not finite; `field` names it.
    InvalidArgument {
        /// Which argument.
        field: Field,
    },
    /// The command is not allowed in the current mode.
    WrongMode {
        /// The current mode.
        mode: Mode,
    },
    /// The target cannot be reached within the model and pressure limits.
    Unreachable,
    /// The calibration fit failed.
    CalibrationFailed(CalibrationError),
}

/// Names of command fields in [`ProtocolError::InvalidArgument`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Field {
    /// A gain.
    Gain,
    /// A pressure limit.
    PressureLimit,
    /// The slew rate.
    SlewRate,
    /// The link timeout.
    LinkTimeout,
    /// Stuck-sensor tick count.
    StuckTicks,
    /// A geometry parameter.
    Geometry,
    /// The number of segments in a target.
    TargetSegments,
    /// A target value.
    TargetValue,
    /// A load value.
    Load,
    /// An actuator index.
    Actuator,
    /// The number of channels in a sensor frame.
    SensorChannels,
}

/// Why a calibration fit failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum CalibrationError {
    /// Fewer than three usable points.
    TooFewPoints,
    /// All codes equal: the slope is undefined.
    Degenerate,
    /// A reference length is outside the plausible actuator range.
    LengthOutOfRange,
    /// The fit explains too little of the variance.
    PoorFit {
        /// R^2 reached, Q1.15.
        r2_q15: u16,
    },
}
