//! Control tables of the servos paper B's rig uses: the fields the joint agent reads and
//! writes, with their addresses and sizes (ROBOTIS e-manual).

/// A field of a control table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    pub address: u16,
    pub size: u16,
    /// Whether a client may write it.
    pub writable: bool,
}

const fn ro(address: u16, size: u16) -> Field {
    Field {
        address,
        size,
        writable: false,
    }
}

const fn rw(address: u16, size: u16) -> Field {
    Field {
        address,
        size,
        writable: true,
    }
}

/// A servo model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Model {
    pub name: &'static str,
    pub number: u16,
    /// Dynamixel protocol: 1 or 2.
    pub protocol: u8,
    pub model_number: Field,
    pub firmware: Field,
    pub id: Field,
    pub baud_rate: Field,
    pub torque_enable: Field,
    pub goal_position: Field,
    pub present_position: Field,
    /// Present current, where the model reports it, with its unit [µA per count] and the
    /// datasheet's stall torque [mN·m] and stall current [mA] at 12 V (0 where it has none).
    pub present_current: Option<Field>,
    pub current_ua_per_count: u32,
    pub stall_torque_mnm: u32,
    pub stall_current_ma: u32,
    /// Size of the table (bytes).
    pub table_size: u16,
    /// Position counts per revolution.
    pub counts_per_rev: u32,
    /// Largest goal position (counts); positions run from 0.
    pub max_position: u32,
    /// The count at 0 rad.
    pub center: u32,
}

/// XH540-W150 (protocol 2.0): paper B's joint motor.
pub const XH540_W150: Model = Model {
    name: "XH540-W150",
    number: 1110,
    protocol: 2,
    model_number: ro(0, 2),
    firmware: ro(6, 1),
    id: rw(7, 1),
    baud_rate: rw(8, 1),
    torque_enable: rw(64, 1),
    goal_position: rw(116, 4),
    present_position: ro(132, 4),
    // e-Manual: Present Current (126), 2.69 mA per count, signed; stall 7.3 N·m at 4.4 A (12 V).
    present_current: Some(ro(126, 2)),
    current_ua_per_count: 2690,
    stall_torque_mnm: 7300,
    stall_current_ma: 4400,
    table_size: 147,
    counts_per_rev: 4096,
    max_position: 4095,
    center: 2048,
};

/// AX-12A (protocol 1.0): paper B's pivot servo.
pub const AX_12A: Model = Model {
    name: "AX-12A",
    number: 12,
    protocol: 1,
    model_number: ro(0, 2),
    firmware: ro(2, 1),
    id: rw(3, 1),
    baud_rate: rw(4, 1),
    torque_enable: rw(24, 1),
    goal_position: rw(30, 2),
    present_position: ro(36, 2),
    present_current: None,
    current_ua_per_count: 0,
    stall_torque_mnm: 0,
    stall_current_ma: 0,
    table_size: 50,
    // 0..1023 over 300°.
    counts_per_rev: 1228,
    max_position: 1023,
    center: 512,
};

/// The models known, for `rig scan` and config checks.
pub const MODELS: [Model; 2] = [XH540_W150, AX_12A];

/// The model with this model number.
pub fn by_number(number: u16) -> Option<&'static Model> {
    MODELS.iter().find(|m| m.number == number)
}

/// The model of this name (as in the config's `main_model`, `stiffness_model`).
pub fn by_name(name: &str) -> Option<&'static Model> {
    MODELS.iter().find(|m| m.name.eq_ignore_ascii_case(name))
}

impl Model {
    /// Motor torque per count of present current [N·m]: the count's current times the
    /// datasheet's stall torque over stall current (its performance graph is close to linear;
    /// the no-load current is not taken off). 0 for a model without a current sensor.
    pub fn nm_per_current_count(&self) -> f64 {
        if self.stall_current_ma == 0 {
            return 0.0;
        }
        f64::from(self.current_ua_per_count) * 1e-6 * f64::from(self.stall_torque_mnm)
            / f64::from(self.stall_current_ma)
    }

    /// Counts to an angle [rad] from the center.
    pub fn to_rad(&self, counts: u32) -> f64 {
        (f64::from(counts) - f64::from(self.center)) * std::f64::consts::TAU
            / f64::from(self.counts_per_rev)
    }

    /// An angle [rad] from the center to counts, or None outside the servo's range.
    pub fn to_counts(&self, rad: f64) -> Option<u32> {
        let c = (rad * f64::from(self.counts_per_rev) / std::f64::consts::TAU
            + f64::from(self.center))
        .round();
        (rad.is_finite() && c >= 0.0 && c <= f64::from(self.max_position)).then_some(c as u32)
    }

    /// Whether [address, address + size) lies in writable fields only.
    pub fn may_write(&self, address: u16, size: u16) -> bool {
        let fields = [
            self.id,
            self.baud_rate,
            self.torque_enable,
            self.goal_position,
        ];
        (address..address.saturating_add(size)).all(|a| {
            fields
                .iter()
                .any(|f| f.writable && a >= f.address && a < f.address + f.size)
        })
    }
}
