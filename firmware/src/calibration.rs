//! Tank sensor calibration: the correction the control core applies to the
//! filtered readings, the flash record that keeps it across resets, and the
//! store the board writes the record with.
//!
//! # Correction
//!
//! Per sensor, on the filtered reading of its nominal transfer function
//! ([`crate::sensor::FrontEnd`], then [`crate::control::filter`]):
//!
//! ```text
//! calibrated = (reading - zero) * gain_ppm / 1 000 000      (rounded toward zero)
//! ```
//!
//! before every safety check (limits, pump monitor, regulation, telemetry).
//! The gain is the calibration's; the zero ([`choose_zero`]) is
//!
//! - before the boot zero: the calibration's `offset_pa`;
//! - from the boot zero on: the filtered reading of atmosphere taken
//!   [`crate::control::ZERO_AT_TICK`] ms after boot (pumps off, valves
//!   closed) **if** it lies within [`crate::Config::zero_window_pa`]
//!   (±4 kPa) of the calibration's offset, else the offset (a tank still
//!   under pressure after a reset, or no valid reading).
//!
//! So the stored offset centres the boot zero's window and stands in for it
//! when the boot reading cannot be atmosphere; the boot zero follows the
//! sensor's drift since the calibration. A calibration set by the host
//! while running is judged against the same boot reading at once.
//!
//! # Record
//!
//! 28 bytes at the start of the last 1 KB flash page (see
//! [`CALIBRATION_PAGE_ADDRESS`]), little-endian:
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 4 | magic [`RECORD_MAGIC`] (ASCII `DXCL`) |
//! | 4 | 2 | version [`RECORD_VERSION`] |
//! | 6 | 2 | payload length (16 in version 1) |
//! | 8 | 4 | positive sensor offset, Pa (`i32`) |
//! | 12 | 4 | positive sensor gain, ppm (`u32`) |
//! | 16 | 4 | negative sensor offset, Pa (`i32`) |
//! | 20 | 4 | negative sensor gain, ppm (`u32`) |
//! | 24 | 4 | CRC-32C of bytes 0..24 (the wire's CRC, bitwise: no table) |
//!
//! [`decode`] ignores (and reports, [`CalibrationRecord`]) an erased page,
//! anything without the magic, a length that overruns the page, a bad CRC,
//! an unknown version and implausible values; the identity calibration
//! applies then.

use dexitac_protocol::{
    ActiveZero, Calibration, CalibrationRecord, SensorCalibration, ZeroSource, GAIN_UNITY_PPM,
};

use crate::sensor::{SENSOR_MAX_PA, SENSOR_MIN_PA};

/// Address of the flash page that holds the record: the last 1 KB page of
/// the STM32F103C8's 64 KB. The root `memory.x` ends the linker's `FLASH`
/// region below it, so no firmware image can overwrite it (test
/// `memory_x_keeps_the_calibration_page_out_of_the_image`).
pub const CALIBRATION_PAGE_ADDRESS: u32 = 0x0800_FC00;
/// Size of a flash page of the STM32F103C8 (medium density), in bytes.
pub const FLASH_PAGE_LEN: usize = 1024;
/// Offset of the record's page from the start of flash (0x0800_0000).
pub const CALIBRATION_PAGE_OFFSET: u32 = CALIBRATION_PAGE_ADDRESS - 0x0800_0000;

/// Marks a record: ASCII "DXCL" read as a little-endian `u32`.
pub const RECORD_MAGIC: u32 = u32::from_le_bytes(*b"DXCL");
/// The record format this firmware writes and reads.
pub const RECORD_VERSION: u16 = 1;
/// Bytes before the payload: magic, version, payload length.
pub const RECORD_HEADER_LEN: usize = 8;
/// Payload bytes of a version 1 record: offset and gain of both sensors.
pub const RECORD_PAYLOAD_LEN: usize = 16;
/// Bytes of the CRC after the payload.
pub const RECORD_CRC_LEN: usize = 4;
/// Bytes of a version 1 record (a whole number of flash half-words).
pub const RECORD_LEN: usize = RECORD_HEADER_LEN + RECORD_PAYLOAD_LEN + RECORD_CRC_LEN;

// The record fits its page and is programmed in whole half-words.
const _: () = assert!(RECORD_LEN <= FLASH_PAGE_LEN && RECORD_LEN % 2 == 0);

/// CRC-32C (Castagnoli), as on the wire, computed bit by bit: the record
/// is read once at boot and written rarely, so no 1 KB table in flash.
const CRC32C: crc::Crc<u32, crc::NoTable> = crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISCSI);

/// The record for `calibration`.
pub fn encode(calibration: &Calibration) -> [u8; RECORD_LEN] {
    let mut record = [0u8; RECORD_LEN];
    let fields: [&[u8]; 7] = [
        &RECORD_MAGIC.to_le_bytes(),
        &RECORD_VERSION.to_le_bytes(),
        // RECORD_PAYLOAD_LEN is 16.
        &(RECORD_PAYLOAD_LEN as u16).to_le_bytes(),
        &calibration.positive.offset_pa.to_le_bytes(),
        &calibration.positive.gain_ppm.to_le_bytes(),
        &calibration.negative.offset_pa.to_le_bytes(),
        &calibration.negative.gain_ppm.to_le_bytes(),
    ];
    let mut at = 0;
    for field in fields {
        if let Some(slot) = record.get_mut(at..at + field.len()) {
            slot.copy_from_slice(field);
        }
        at += field.len();
    }
    let crc = CRC32C.checksum(record.get(..at).unwrap_or(&[]));
    if let Some(slot) = record.get_mut(at..at + RECORD_CRC_LEN) {
        slot.copy_from_slice(&crc.to_le_bytes());
    }
    record
}

/// What a flash page held: the calibration, if it is a valid record, and
/// the state to report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Loaded {
    /// The stored calibration; `None` when the record is not usable.
    pub calibration: Option<Calibration>,
    /// What the page held ([`CalibrationRecord::Valid`] with a calibration).
    pub record: CalibrationRecord,
}

impl Loaded {
    const fn ignored(record: CalibrationRecord) -> Loaded {
        Loaded {
            calibration: None,
            record,
        }
    }
}

fn u16_at(bytes: &[u8], at: usize) -> Option<u16> {
    let b: [u8; 2] = bytes.get(at..at + 2)?.try_into().ok()?;
    Some(u16::from_le_bytes(b))
}

fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    let b: [u8; 4] = bytes.get(at..at + 4)?.try_into().ok()?;
    Some(u32::from_le_bytes(b))
}

fn i32_at(bytes: &[u8], at: usize) -> Option<i32> {
    let b: [u8; 4] = bytes.get(at..at + 4)?.try_into().ok()?;
    Some(i32::from_le_bytes(b))
}

/// Reads the record at the start of `page` (the flash page, or at least
/// the record's bytes). Never panics: every byte pattern gives a state.
pub fn decode(page: &[u8]) -> Loaded {
    let Some(magic) = u32_at(page, 0) else {
        return Loaded::ignored(CalibrationRecord::NotARecord);
    };
    if magic == u32::MAX {
        // Erased flash reads as 0xFF.
        return Loaded::ignored(CalibrationRecord::Empty);
    }
    if magic != RECORD_MAGIC {
        return Loaded::ignored(CalibrationRecord::NotARecord);
    }
    let (Some(version), Some(payload_len)) = (u16_at(page, 4), u16_at(page, 6)) else {
        return Loaded::ignored(CalibrationRecord::NotARecord);
    };
    // The CRC covers header and payload; a length that runs off the page is
    // as good as a bad CRC (the length itself is what is corrupt).
    let crc_at = RECORD_HEADER_LEN + usize::from(payload_len);
    let (Some(covered), Some(stored_crc)) = (page.get(..crc_at), u32_at(page, crc_at)) else {
        return Loaded::ignored(CalibrationRecord::BadCrc);
    };
    if CRC32C.checksum(covered) != stored_crc {
        return Loaded::ignored(CalibrationRecord::BadCrc);
    }
    if version != RECORD_VERSION {
        return Loaded::ignored(CalibrationRecord::UnknownVersion { version });
    }
    if usize::from(payload_len) != RECORD_PAYLOAD_LEN {
        return Loaded::ignored(CalibrationRecord::NotARecord);
    }
    let sensor = |at: usize| {
        Some(SensorCalibration {
            offset_pa: i32_at(page, at)?,
            gain_ppm: u32_at(page, at + 4)?,
        })
    };
    let (Some(positive), Some(negative)) =
        (sensor(RECORD_HEADER_LEN), sensor(RECORD_HEADER_LEN + 8))
    else {
        return Loaded::ignored(CalibrationRecord::NotARecord);
    };
    let calibration = Calibration { positive, negative };
    if calibration.check().is_err() {
        return Loaded::ignored(CalibrationRecord::Implausible { version });
    }
    Loaded {
        calibration: Some(calibration),
        record: CalibrationRecord::Valid { version },
    }
}

/// `reading_pa` corrected by `zero_pa` and `gain_ppm`, clamped to the
/// sensor's range (a reading that far out is past both tank limits anyway).
pub fn correct(reading_pa: i32, zero_pa: i32, gain_ppm: u32) -> i32 {
    // Saturating: only values far outside the sensor range (never a
    // reading) can reach the ends, and they clamp below either way.
    let scaled = (i64::from(reading_pa) - i64::from(zero_pa)).saturating_mul(i64::from(gain_ppm))
        / i64::from(GAIN_UNITY_PPM);
    let clamped = scaled.clamp(i64::from(SENSOR_MIN_PA), i64::from(SENSOR_MAX_PA));
    // Clamped to the sensor range, which fits an i32.
    i32::try_from(clamped).unwrap_or(0)
}

/// The zero a sensor is corrected by: the boot zero (`boot_reading_pa`,
/// `None` before the boot zero or without a valid settled reading then)
/// when it lies within `window_pa` of the calibration's offset, else the
/// offset. `zeroed`: whether the boot zero has been taken.
pub fn choose_zero(
    sensor: SensorCalibration,
    boot_reading_pa: Option<i32>,
    zeroed: bool,
    window_pa: i32,
) -> ActiveZero {
    let offset = ActiveZero {
        zero_pa: sensor.offset_pa,
        source: if zeroed {
            ZeroSource::Offset
        } else {
            ZeroSource::Pending
        },
    };
    match boot_reading_pa {
        Some(pa)
            if zeroed
                && (i64::from(pa) - i64::from(sensor.offset_pa)).abs() <= i64::from(window_pa) =>
        {
            ActiveZero {
                zero_pa: pa,
                source: ZeroSource::Boot,
            }
        }
        _ => offset,
    }
}

/// Why a record was not stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreError {
    /// This build has no place for the record (the QEMU build): reported
    /// as [`CalibrationRecord::NotPersisted`].
    NotPersisted,
    /// Erasing, programming or verifying the page failed: reported as
    /// [`CalibrationRecord::WriteFailed`].
    Failed,
}

/// Where the board keeps the record: the last flash page on the board, RAM
/// in the host simulator, nothing in the QEMU build.
///
/// [`crate::Controller::store_calibration`] calls it only while the MCU is
/// not armed and both pumps are off: on the STM32F103 a page erase stalls
/// the CPU (and so the control loop) for up to 40 ms.
pub trait CalibrationStore {
    /// Writes `record` (erasing what was there). Should return `Ok` without
    /// writing when the stored bytes already equal `record`.
    fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), StoreError>;
}

/// A store that keeps nothing (the QEMU build): every write reports
/// [`StoreError::NotPersisted`].
#[derive(Debug, Clone, Copy, Default)]
pub struct NoStore;

impl CalibrationStore for NoStore {
    fn write_record(&mut self, _record: &[u8; RECORD_LEN]) -> Result<(), StoreError> {
        Err(StoreError::NotPersisted)
    }
}

/// A flash page in RAM, erased (0xFF) at first: the host simulator's store,
/// and the tests'. [`CalibrationStore::write_record`] erases it and writes
/// the record at its start, as the board does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RamPage {
    /// The page's bytes.
    pub bytes: [u8; FLASH_PAGE_LEN],
    /// Records written (unchanged records are not written again).
    pub writes: u32,
}

impl Default for RamPage {
    fn default() -> Self {
        RamPage {
            bytes: [0xFF; FLASH_PAGE_LEN],
            writes: 0,
        }
    }
}

impl CalibrationStore for RamPage {
    fn write_record(&mut self, record: &[u8; RECORD_LEN]) -> Result<(), StoreError> {
        if self.bytes.get(..RECORD_LEN) == Some(record.as_slice()) {
            return Ok(());
        }
        self.bytes = [0xFF; FLASH_PAGE_LEN];
        let slot = self.bytes.get_mut(..RECORD_LEN).ok_or(StoreError::Failed)?;
        slot.copy_from_slice(record);
        self.writes = self.writes.wrapping_add(1);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dexitac_protocol::{
        CALIBRATION_GAIN_MAX_PPM, CALIBRATION_GAIN_MIN_PPM, CALIBRATION_OFFSET_MAX_PA,
    };
    use proptest::prelude::*;

    fn example() -> Calibration {
        Calibration {
            positive: SensorCalibration {
                offset_pa: 1_200,
                gain_ppm: 1_050_000,
            },
            negative: SensorCalibration {
                offset_pa: -800,
                gain_ppm: 980_000,
            },
        }
    }

    fn plausible_sensor() -> impl Strategy<Value = SensorCalibration> {
        (
            -CALIBRATION_OFFSET_MAX_PA..=CALIBRATION_OFFSET_MAX_PA,
            CALIBRATION_GAIN_MIN_PPM..=CALIBRATION_GAIN_MAX_PPM,
        )
            .prop_map(|(offset_pa, gain_ppm)| SensorCalibration {
                offset_pa,
                gain_ppm,
            })
    }

    fn plausible() -> impl Strategy<Value = Calibration> {
        (plausible_sensor(), plausible_sensor())
            .prop_map(|(positive, negative)| Calibration { positive, negative })
    }

    /// The linker's FLASH region (root `memory.x`) ends at or before the
    /// record's page, and the page is the part's last.
    #[test]
    fn memory_x_keeps_the_calibration_page_out_of_the_image() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../memory.x");
        let text = std::fs::read_to_string(path).expect("the root memory.x");
        let flash = text
            .lines()
            .find(|l| l.trim_start().starts_with("FLASH"))
            .expect("a FLASH line");
        let number = |key: &str| {
            let rest = flash.split(key).nth(1).expect(key);
            let token: std::string::String = rest
                .trim_start_matches([' ', '='])
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric())
                .collect();
            match token.strip_suffix('K') {
                Some(kb) => kb.parse::<u32>().expect("size") * 1024,
                None => u32::from_str_radix(token.trim_start_matches("0x"), 16).expect("address"),
            }
        };
        let (origin, length) = (number("ORIGIN"), number("LENGTH"));
        assert_eq!(origin, 0x0800_0000);
        assert!(
            origin + length <= CALIBRATION_PAGE_ADDRESS,
            "FLASH ends at {:#x}, past the calibration page at {CALIBRATION_PAGE_ADDRESS:#x}",
            origin + length
        );
        // The last 1 KB page of the 64 KB part, page-aligned.
        assert_eq!(
            CALIBRATION_PAGE_ADDRESS as usize + FLASH_PAGE_LEN,
            0x0801_0000
        );
        assert_eq!(CALIBRATION_PAGE_ADDRESS as usize % FLASH_PAGE_LEN, 0);
    }

    #[test]
    fn record_layout_is_as_documented() {
        let record = encode(&example());
        assert_eq!(RECORD_LEN, 28);
        assert_eq!(&record[0..4], b"DXCL");
        assert_eq!(record[4..6], [1, 0], "version 1");
        assert_eq!(record[6..8], [16, 0], "payload length");
        assert_eq!(record[8..12], 1_200i32.to_le_bytes());
        assert_eq!(record[12..16], 1_050_000u32.to_le_bytes());
        assert_eq!(record[16..20], (-800i32).to_le_bytes());
        assert_eq!(record[20..24], 980_000u32.to_le_bytes());
        // CRC-32C, as the protocol's table-driven one computes it.
        let table = crc::Crc::<u32>::new(&crc::CRC_32_ISCSI);
        assert_eq!(record[24..28], table.checksum(&record[..24]).to_le_bytes());
    }

    #[test]
    fn erased_page_foreign_bytes_and_short_pages_are_reported() {
        assert_eq!(
            decode(&[0xFF; FLASH_PAGE_LEN]).record,
            CalibrationRecord::Empty
        );
        assert_eq!(
            decode(&[0x00; FLASH_PAGE_LEN]).record,
            CalibrationRecord::NotARecord
        );
        assert_eq!(decode(&[]).record, CalibrationRecord::NotARecord);
        // The magic, then the page ends: the CRC cannot be checked.
        let record = encode(&example());
        assert_eq!(decode(&record[..10]).record, CalibrationRecord::BadCrc);
        assert_eq!(decode(&record[..10]).calibration, None);
    }

    #[test]
    fn wrong_version_with_a_valid_crc_is_ignored_and_reported() {
        let mut record = encode(&example());
        record[4..6].copy_from_slice(&2u16.to_le_bytes());
        let crc = CRC32C.checksum(&record[..24]);
        record[24..28].copy_from_slice(&crc.to_le_bytes());
        let loaded = decode(&record);
        assert_eq!(loaded.calibration, None);
        assert_eq!(
            loaded.record,
            CalibrationRecord::UnknownVersion { version: 2 }
        );
    }

    #[test]
    fn a_longer_record_of_a_later_version_is_checked_by_its_own_length() {
        // Version 7 with 20 payload bytes: its CRC sits after them.
        let mut page = [0xFFu8; FLASH_PAGE_LEN];
        page[0..4].copy_from_slice(b"DXCL");
        page[4..6].copy_from_slice(&7u16.to_le_bytes());
        page[6..8].copy_from_slice(&20u16.to_le_bytes());
        page[8..28].fill(0x11);
        let crc = CRC32C.checksum(&page[..28]);
        page[28..32].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(
            decode(&page).record,
            CalibrationRecord::UnknownVersion { version: 7 }
        );
    }

    #[test]
    fn implausible_values_with_a_valid_crc_are_ignored() {
        let mut cal = example();
        cal.negative.gain_ppm = 2_000_000;
        let loaded = decode(&encode(&cal));
        assert_eq!(loaded.calibration, None);
        assert_eq!(
            loaded.record,
            CalibrationRecord::Implausible {
                version: RECORD_VERSION
            }
        );
    }

    #[test]
    fn ram_page_skips_unchanged_records() {
        let mut page = RamPage::default();
        let record = encode(&example());
        assert_eq!(page.write_record(&record), Ok(()));
        assert_eq!(page.write_record(&record), Ok(()));
        assert_eq!(page.writes, 1);
        assert_eq!(decode(&page.bytes).calibration, Some(example()));
        assert_eq!(NoStore.write_record(&record), Err(StoreError::NotPersisted));
    }

    #[test]
    fn correction_subtracts_the_zero_then_applies_the_gain() {
        assert_eq!(correct(10_000, 0, GAIN_UNITY_PPM), 10_000);
        assert_eq!(correct(10_000, 1_000, GAIN_UNITY_PPM), 9_000);
        assert_eq!(correct(10_000, 0, 1_050_000), 10_500);
        assert_eq!(correct(-20_000, 1_000, 1_100_000), -23_100);
        // Far outside: clamped to the sensor range, no overflow.
        assert_eq!(correct(i32::MAX, i32::MIN, u32::MAX), SENSOR_MAX_PA);
        assert_eq!(correct(i32::MIN, i32::MAX, u32::MAX), SENSOR_MIN_PA);
    }

    #[test]
    fn the_boot_zero_applies_inside_the_window_around_the_offset() {
        let sensor = SensorCalibration {
            offset_pa: 7_000,
            gain_ppm: GAIN_UNITY_PPM,
        };
        let zero = |boot, zeroed| choose_zero(sensor, boot, zeroed, 4_000);
        // Before the boot zero: the offset.
        assert_eq!(zero(None, false).source, ZeroSource::Pending);
        assert_eq!(zero(Some(7_500), false).zero_pa, 7_000);
        // Within ±4 kPa of the 7 kPa offset: the boot reading (a sensor with
        // a 7 kPa zero error, which the nominal window would not accept).
        let z = zero(Some(9_500), true);
        assert_eq!((z.zero_pa, z.source), (9_500, ZeroSource::Boot));
        // Further (a tank under pressure at boot) or no reading: the offset.
        let z = zero(Some(11_001), true);
        assert_eq!((z.zero_pa, z.source), (7_000, ZeroSource::Offset));
        let z = zero(None, true);
        assert_eq!((z.zero_pa, z.source), (7_000, ZeroSource::Offset));
        // Extreme values do not overflow the comparison.
        let z = choose_zero(
            SensorCalibration {
                offset_pa: i32::MIN,
                gain_ppm: 0,
            },
            Some(i32::MAX),
            true,
            i32::MAX,
        );
        assert_eq!(z.source, ZeroSource::Offset);
    }

    proptest! {
        /// Every plausible calibration survives the record, alone on an
        /// erased page or at the start of any bytes.
        #[test]
        fn record_round_trips(cal in plausible(), tail in proptest::collection::vec(any::<u8>(), 0..64)) {
            let record = encode(&cal);
            let mut page = record.to_vec();
            page.extend_from_slice(&tail);
            let loaded = decode(&page);
            prop_assert_eq!(loaded.calibration, Some(cal));
            prop_assert_eq!(loaded.record, CalibrationRecord::Valid { version: RECORD_VERSION });
        }

        /// Any corrupted byte (any non-zero XOR) of a record is detected:
        /// never a calibration, and never one that differs from the stored.
        #[test]
        fn a_corrupted_byte_is_never_read_as_a_calibration(
            cal in plausible(),
            at in 0..RECORD_LEN,
            flip in 1u8..=255,
        ) {
            let mut record = encode(&cal);
            record[at] ^= flip;
            let loaded = decode(&record);
            prop_assert_eq!(loaded.calibration, None, "byte {} ^ {:#x}: {:?}", at, flip, loaded.record);
            prop_assert!(
                !matches!(loaded.record, CalibrationRecord::Valid { .. } | CalibrationRecord::Empty),
                "{:?}", loaded.record
            );
        }

        /// Two corrupted bytes are detected too (CRC-32C: any error burst
        /// of up to 32 bits, and any two-bit error in a record this short).
        #[test]
        fn two_corrupted_bits_are_detected(
            cal in plausible(),
            a in 0..RECORD_LEN * 8,
            b in 0..RECORD_LEN * 8,
        ) {
            prop_assume!(a != b);
            let mut record = encode(&cal);
            record[a / 8] ^= 1 << (a % 8);
            record[b / 8] ^= 1 << (b % 8);
            prop_assert_eq!(decode(&record).calibration, None);
        }

        /// Arbitrary bytes never panic the decoder and are accepted only as
        /// a plausible calibration whose record they are.
        #[test]
        fn arbitrary_pages_decode_without_panic(page in proptest::collection::vec(any::<u8>(), 0..80)) {
            let loaded = decode(&page);
            if let Some(cal) = loaded.calibration {
                prop_assert!(cal.check().is_ok());
                prop_assert_eq!(&encode(&cal)[..], &page[..RECORD_LEN]);
            }
        }

        /// The correction is monotonic in the reading (a higher pressure
        /// never reads lower) for every plausible calibration.
        #[test]
        fn correction_is_monotonic(
            sensor in plausible_sensor(),
            a in SENSOR_MIN_PA..=SENSOR_MAX_PA,
            b in SENSOR_MIN_PA..=SENSOR_MAX_PA,
        ) {
            let (lo, hi) = (a.min(b), a.max(b));
            prop_assert!(
                correct(lo, sensor.offset_pa, sensor.gain_ppm)
                    <= correct(hi, sensor.offset_pa, sensor.gain_ppm)
            );
        }
    }
}
