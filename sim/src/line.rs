//! A noisy serial line: wraps a port and flips random bits in the bytes
//! that pass, in both directions, with a seeded generator.
//!
//! Used by the simulated rig ([`crate::rig::SimOptions::line_error_rate`])
//! to check that corrupted frames never actuate anything: the protocol's CRC
//! drops them and the link's retries resend commands.

use std::io::{self, Read, Write};

use dexitac_tactile::synth::Rng;

/// A port whose bytes are corrupted with probability `rate` each.
pub struct NoisyPort<P> {
    inner: P,
    rate: f64,
    rng: Rng,
    corrupted: u64,
}

impl<P> NoisyPort<P> {
    /// Wraps `inner`; each byte read or written is corrupted with
    /// probability `rate` (clamped to 0..=1).
    pub fn new(inner: P, rate: f64, seed: u64) -> Self {
        NoisyPort {
            inner,
            rate: if rate.is_finite() {
                rate.clamp(0.0, 1.0)
            } else {
                0.0
            },
            rng: Rng::new(seed),
            corrupted: 0,
        }
    }

    /// Bytes corrupted so far.
    pub fn corrupted(&self) -> u64 {
        self.corrupted
    }

    fn corrupt(&mut self, bytes: &mut [u8]) {
        for b in bytes {
            if self.rng.unit() < self.rate {
                // A non-zero mask: the byte always changes.
                *b ^= (self.rng.next_u64() % 255 + 1) as u8;
                self.corrupted += 1;
            }
        }
    }
}

impl<P: Read> Read for NoisyPort<P> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        if let Some(got) = buf.get_mut(..n) {
            self.corrupt(got);
        }
        Ok(n)
    }
}

impl<P: Write> Write for NoisyPort<P> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut noisy = buf.to_vec();
        self.corrupt(&mut noisy);
        self.inner.write_all(&noisy)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corrupts_about_the_requested_fraction() {
        let mut port = NoisyPort::new(Vec::new(), 0.01, 3);
        port.write_all(&[0u8; 100_000]).unwrap();
        let changed = port.inner.iter().filter(|&&b| b != 0).count() as u64;
        assert_eq!(changed, port.corrupted());
        assert!((700..1_300).contains(&changed), "{changed}");
    }
}
