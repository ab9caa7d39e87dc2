//! `dexitac calibrate`: the tank pressure sensors' calibration on the board
//! (a zero offset and a gain per sensor, `HostMsg::SetCalibration`).
//!
//! The firmware corrects every filtered reading as `(reading - zero) * gain`
//! before its safety checks; `zero` is the boot zero when the reading at
//! boot lies within 4 kPa of the calibration's offset, else the offset
//! (firmware/README.md, "Sensor calibration"). The board stores the
//! calibration in flash and reports it in its hello reply.
//!
//! - `--show` (or no values): print the board's calibration.
//! - `--offset-kpa POS,NEG` and/or `--gain POS,NEG`: set them (a value not
//!   given keeps the board's), then read them back.
//! - `--zero`: take the offsets from 0.5 s of telemetry with the pumps off,
//!   as the sensors' readings of atmosphere. **The tanks must be open to
//!   atmosphere**: pumps off alone leaves a sealed tank under pressure.
//!
//! A calibration moves the trip points of the safety loop, so the board
//! accepts one only while disarmed, and only within ±10 kPa and 0.9..1.1
//! (`dexitac_protocol::limits`).
//!
//! Exit 0 when the calibration was applied and stored (or, with `--show`,
//! the board's record is sound), 1 when it was applied but not stored (the
//! QEMU build keeps no record, or the flash write failed) or, with
//! `--show`, the stored record was ignored (bad CRC, unknown version, ...),
//! 2 when the board cannot be reached, refuses (armed, faults latched) or
//! the values are out of range.

use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context};
use dexitac_protocol::{
    ActiveZero, ArmState, Calibration, CalibrationError, CalibrationRecord, CalibrationReport,
    CalibrationSource, HostMsg, NackReason, SensorCalibration, ZeroSource,
    CALIBRATION_GAIN_MAX_PPM, CALIBRATION_GAIN_MIN_PPM, CALIBRATION_OFFSET_MAX_PA, GAIN_UNITY_PPM,
    NO_READING_PA,
};
use dexitac_rig::link::{Link, LinkError, McuEvent, Port};

use crate::exit::Outcome;
use crate::shared::board::BoardArgs;

/// How long `--zero` averages the telemetry.
const ZERO_SPAN: Duration = Duration::from_millis(500);
/// Telemetry interval while `--zero` averages, ms.
const ZERO_TELEMETRY_MS: u16 = 20;
/// Fewest telemetry frames `--zero` averages.
const ZERO_MIN_FRAMES: usize = 10;
/// Largest spread of one tank's readings `--zero` accepts, Pa: more means
/// the tank is not settled at atmosphere.
const ZERO_MAX_SPREAD_PA: i32 = 2_000;

/// A value for each tank sensor: `POS,NEG`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerSensor {
    /// The positive tank's sensor.
    pub positive: f64,
    /// The negative tank's sensor.
    pub negative: f64,
}

fn parse_per_sensor(text: &str) -> Result<PerSensor, String> {
    let values: Vec<&str> = text.split(',').map(str::trim).collect();
    let [positive, negative] = values[..] else {
        return Err(format!(
            "give two values, positive and negative sensor (e.g. `1.2,-0.8`), not `{text}`"
        ));
    };
    let number = |s: &str| match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("`{s}` is not a number")),
    };
    Ok(PerSensor {
        positive: number(positive)?,
        negative: number(negative)?,
    })
}

/// Arguments of `dexitac calibrate`.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    board: BoardArgs,
    /// Print the board's calibration (from its hello reply) and change
    /// nothing; the default when no value is given.
    #[arg(long, conflicts_with_all = ["offset_kpa", "gain", "zero"])]
    show: bool,
    /// Zero offsets to set, in kPa: each sensor's reading of atmosphere,
    /// subtracted from its readings (positive,negative; within ±10 kPa).
    /// Default: the board's.
    #[arg(long, value_name = "POS,NEG", value_parser = parse_per_sensor, allow_hyphen_values = true)]
    offset_kpa: Option<PerSensor>,
    /// Gains to set (positive,negative; within 0.9..1.1), applied after
    /// the zero. Default: the board's.
    #[arg(long, value_name = "POS,NEG", value_parser = parse_per_sensor)]
    gain: Option<PerSensor>,
    /// Set the offsets to what the sensors read now: the mean of 0.5 s of
    /// telemetry, board disarmed, pumps off. The tanks must be open to
    /// atmosphere (pumps off alone leaves a sealed tank under pressure).
    #[arg(long, conflicts_with = "offset_kpa")]
    zero: bool,
}

/// `value` kPa in pascal, if it is a sensible number.
fn offset_pa(kpa: f64, tank: &str) -> anyhow::Result<i32> {
    let pa = (kpa * 1e3).round();
    if !(f64::from(i32::MIN)..=f64::from(i32::MAX)).contains(&pa) {
        bail!("{tank} offset {kpa} kPa is outside ±{CALIBRATION_OFFSET_MAX_PA} Pa");
    }
    Ok(pa as i32)
}

/// `gain` in parts per million, if it is a sensible number.
fn gain_ppm(gain: f64, tank: &str) -> anyhow::Result<u32> {
    let ppm = (gain * f64::from(GAIN_UNITY_PPM)).round();
    if !(0.0..=f64::from(u32::MAX)).contains(&ppm) {
        bail!("{tank} gain {gain} is outside {}", gain_range());
    }
    Ok(ppm as u32)
}

fn gain_range() -> String {
    format!(
        "{}..{}",
        f64::from(CALIBRATION_GAIN_MIN_PPM) / 1e6,
        f64::from(CALIBRATION_GAIN_MAX_PPM) / 1e6
    )
}

/// A calibration the firmware would refuse, in the command line's units.
fn implausible(e: CalibrationError) -> anyhow::Error {
    let offset = |tank: &str, offset_pa: i32| {
        anyhow!(
            "{tank} sensor offset {:+.3} kPa is outside ±{} kPa: a larger zero error is a broken \
             sensor or a zero taken on a pressurised tank",
            f64::from(offset_pa) / 1e3,
            f64::from(CALIBRATION_OFFSET_MAX_PA) / 1e3
        )
    };
    let gain = |tank: &str, gain_ppm: u32| {
        anyhow!(
            "{tank} sensor gain {:.6} is outside {}: check the sensor and its divider",
            f64::from(gain_ppm) / 1e6,
            gain_range()
        )
    };
    match e {
        CalibrationError::PositiveOffset { offset_pa } => offset("positive", offset_pa),
        CalibrationError::NegativeOffset { offset_pa } => offset("negative", offset_pa),
        CalibrationError::PositiveGain { gain_ppm } => gain("positive", gain_ppm),
        CalibrationError::NegativeGain { gain_ppm } => gain("negative", gain_ppm),
    }
}

fn source_words(source: CalibrationSource) -> &'static str {
    match source {
        CalibrationSource::Default => "default (no stored calibration: offset 0, gain 1)",
        CalibrationSource::Flash => "read from the board's flash at boot",
        CalibrationSource::Host => "set by the host since the board's boot",
    }
}

fn record_words(record: CalibrationRecord) -> String {
    match record {
        CalibrationRecord::NotPersisted => {
            "not persisted: this firmware keeps no record (QEMU build); applies until reset".into()
        }
        CalibrationRecord::Empty => "none stored (the flash page is erased)".into(),
        CalibrationRecord::Valid { version } => {
            format!("stored in flash (record v{version}, CRC valid)")
        }
        CalibrationRecord::BadCrc => "ignored: the stored record fails its CRC".into(),
        CalibrationRecord::UnknownVersion { version } => {
            format!("ignored: the stored record has version {version}, which this firmware does not know")
        }
        CalibrationRecord::NotARecord => {
            "ignored: the flash page holds no calibration record".into()
        }
        CalibrationRecord::Implausible { version } => {
            format!("ignored: the stored record (v{version}) holds values outside the limits")
        }
        CalibrationRecord::WritePending => {
            "waiting to be written (the board arms only after the write)".into()
        }
        CalibrationRecord::WriteFailed => {
            "writing the record failed: the calibration applies until reset".into()
        }
    }
}

fn zero_words(zero: ActiveZero) -> String {
    let kpa = f64::from(zero.zero_pa) / 1e3;
    match zero.source {
        ZeroSource::Pending => format!("{kpa:+.3} kPa (the offset; boot zero not taken yet)"),
        ZeroSource::Boot => format!("{kpa:+.3} kPa (the boot zero, within 4 kPa of the offset)"),
        ZeroSource::Offset => {
            format!("{kpa:+.3} kPa (the offset: the reading at boot was not within 4 kPa of it)")
        }
    }
}

fn print_report(report: &CalibrationReport) {
    println!("calibration: {}", source_words(report.source));
    println!("  record: {}", record_words(report.record));
    for (tank, sensor, zero) in [
        (
            "positive",
            report.calibration.positive,
            report.positive_zero,
        ),
        (
            "negative",
            report.calibration.negative,
            report.negative_zero,
        ),
    ] {
        println!(
            "  {tank} sensor: offset {:+.3} kPa, gain {:.6}; zero in use {}",
            f64::from(sensor.offset_pa) / 1e3,
            f64::from(sensor.gain_ppm) / 1e6,
            zero_words(zero)
        );
    }
}

/// Why the board refused the calibration, for a person.
fn refusal(reason: NackReason) -> anyhow::Error {
    match reason {
        NackReason::Refused => anyhow!(
            "the board is armed: it takes a calibration only while disarmed (stop the task loop first)"
        ),
        NackReason::Tripped => anyhow!(
            "the board has latched faults: acknowledge them first (`dexitac faults --port PORT`)"
        ),
        NackReason::Implausible => anyhow!(
            "the board found the calibration implausible (its limits differ from this host's?)"
        ),
        other => anyhow!("the board refused the calibration: {other:?}"),
    }
}

/// The offsets that make the current readings zero: each tank's mean
/// reading over [`ZERO_SPAN`] of telemetry, taken back through the
/// correction the board applies now (`reading = (raw - zero) * gain`).
fn zero_offsets<P: Port>(
    link: &mut Link<P>,
    report: &CalibrationReport,
) -> anyhow::Result<(i32, i32)> {
    println!(
        "zero: averaging {} ms of telemetry as atmosphere (the tanks must be open to it)",
        ZERO_SPAN.as_millis()
    );
    link.command(HostMsg::SetTelemetryInterval {
        interval_ms: ZERO_TELEMETRY_MS,
    })
    .context("starting telemetry")?;
    let mut frames = Vec::new();
    let until = Instant::now() + ZERO_SPAN;
    while Instant::now() < until {
        for event in link.poll(Duration::from_millis(20))? {
            if let McuEvent::Telemetry(t) = event {
                frames.push(t);
            }
        }
    }
    link.command(HostMsg::SetTelemetryInterval { interval_ms: 0 })
        .context("stopping telemetry")?;
    if frames.len() < ZERO_MIN_FRAMES {
        bail!(
            "only {} telemetry frames in {} ms: the board's telemetry is not coming through",
            frames.len(),
            ZERO_SPAN.as_millis()
        );
    }
    if let Some(t) = frames.iter().find(|t| t.state != ArmState::Disarmed) {
        bail!("the board is {:?}: zero only a disarmed board", t.state);
    }
    if frames
        .iter()
        .any(|t| t.positive_pump_on || t.negative_pump_on)
    {
        bail!("a pump ran while averaging: zero with the pumps off");
    }
    let offset = |tank: &str, readings: Vec<i32>, sensor: SensorCalibration, zero: ActiveZero| {
        if readings.contains(&NO_READING_PA) {
            bail!("the {tank} sensor gave no valid reading: check its wiring");
        }
        let (lo, hi) = readings
            .iter()
            .fold((i32::MAX, i32::MIN), |(lo, hi), &r| (lo.min(r), hi.max(r)));
        if hi.saturating_sub(lo) > ZERO_MAX_SPREAD_PA {
            bail!(
                "the {tank} tank's reading moved {:.1} kPa while averaging: it is not settled at \
                 atmosphere",
                f64::from(hi.saturating_sub(lo)) / 1e3
            );
        }
        let mean = readings.iter().map(|&r| f64::from(r)).sum::<f64>() / readings.len() as f64;
        let gain = f64::from(sensor.gain_ppm.max(1)) / f64::from(GAIN_UNITY_PPM);
        let raw_pa = mean / gain + f64::from(zero.zero_pa);
        println!(
            "  {tank} sensor: reads {:+.3} kPa now -> offset {:+.3} kPa",
            mean / 1e3,
            raw_pa / 1e3
        );
        offset_pa(raw_pa / 1e3, tank)
    };
    let positive = offset(
        "positive",
        frames.iter().map(|t| t.positive_tank_pa).collect(),
        report.calibration.positive,
        report.positive_zero,
    )?;
    let negative = offset(
        "negative",
        frames.iter().map(|t| t.negative_tank_pa).collect(),
        report.calibration.negative,
        report.negative_zero,
    )?;
    Ok((positive, negative))
}

impl CalibrateArgs {
    /// Runs `dexitac calibrate`.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        let mut link = self.board.open()?;
        let hello = link.hello().context("hello")?;
        let before = hello.calibration;
        print_report(&before);
        if self.show || (self.offset_kpa.is_none() && self.gain.is_none() && !self.zero) {
            return Ok(Outcome::from_ok(before.record.is_sound()));
        }

        let mut wanted = before.calibration;
        if let Some(kpa) = self.offset_kpa {
            wanted.positive.offset_pa = offset_pa(kpa.positive, "positive")?;
            wanted.negative.offset_pa = offset_pa(kpa.negative, "negative")?;
        }
        if let Some(gain) = self.gain {
            wanted.positive.gain_ppm = gain_ppm(gain.positive, "positive")?;
            wanted.negative.gain_ppm = gain_ppm(gain.negative, "negative")?;
        }
        if self.zero {
            let (positive, negative) = zero_offsets(&mut link, &before)?;
            wanted.positive.offset_pa = positive;
            wanted.negative.offset_pa = negative;
        }
        wanted.check().map_err(implausible)?;

        match link.command(HostMsg::SetCalibration(wanted)) {
            Ok(()) => {}
            Err(LinkError::Nack { reason, .. }) => return Err(refusal(reason)),
            Err(e) => return Err(e).context("sending the calibration"),
        }
        let after = link
            .hello()
            .context("hello after the calibration")?
            .calibration;
        if after.calibration != wanted {
            bail!(
                "the board reports {} instead of {}",
                describe(&after.calibration),
                describe(&wanted)
            );
        }
        println!("set:");
        print_report(&after);
        Ok(Outcome::from_ok(matches!(
            after.record,
            CalibrationRecord::Valid { .. }
        )))
    }
}

fn describe(c: &Calibration) -> String {
    let one = |s: SensorCalibration| {
        format!(
            "{:+.3} kPa x{:.6}",
            f64::from(s.offset_pa) / 1e3,
            f64::from(s.gain_ppm) / 1e6
        )
    };
    format!("positive {}, negative {}", one(c.positive), one(c.negative))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_sensor_values_parse_and_bad_ones_are_clear_errors() {
        assert_eq!(
            parse_per_sensor("1.2,-0.8"),
            Ok(PerSensor {
                positive: 1.2,
                negative: -0.8
            })
        );
        assert_eq!(parse_per_sensor(" 1 , 2 ").map(|p| p.negative), Ok(2.0));
        assert!(parse_per_sensor("1.2").unwrap_err().contains("two values"));
        assert!(parse_per_sensor("1,2,3")
            .unwrap_err()
            .contains("two values"));
        assert!(parse_per_sensor("1,x")
            .unwrap_err()
            .contains("`x` is not a number"));
        assert!(parse_per_sensor("1,NaN").is_err());
        assert!(parse_per_sensor("inf,1").is_err());
    }

    #[test]
    fn units_convert_and_out_of_range_values_are_named() {
        assert_eq!(offset_pa(1.2345, "positive").unwrap(), 1_235);
        assert_eq!(offset_pa(-0.8, "negative").unwrap(), -800);
        assert_eq!(gain_ppm(1.05, "positive").unwrap(), 1_050_000);
        assert!(offset_pa(1e12, "positive").is_err());
        assert!(gain_ppm(-1.0, "negative").is_err());
        let e = implausible(CalibrationError::NegativeGain {
            gain_ppm: 1_500_000,
        })
        .to_string();
        assert!(
            e.contains("negative sensor gain 1.500000 is outside 0.9..1.1"),
            "{e}"
        );
        let e = implausible(CalibrationError::PositiveOffset { offset_pa: 12_000 }).to_string();
        assert!(
            e.contains("positive sensor offset +12.000 kPa is outside ±10 kPa"),
            "{e}"
        );
    }
}
