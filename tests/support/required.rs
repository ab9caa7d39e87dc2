//! Tests that need something this machine may lack (QEMU, Xvfb): the one
//! way out when it is missing. The test fails when its variable is set
//! (to anything but empty or `0`; `.ci/run` sets it), and otherwise says
//! "skipped" with the reason, straight to stderr, past libtest's output
//! capture (which takes `eprintln!`), so a skip shows in a passing run.
//!
//! Shared by the test crates that need it with `#[path = "..."] mod`: test
//! crates have no common helper crate.

use std::ffi::OsStr;
use std::io::Write;

/// What a test that cannot run does: `Ok(note)` to skip, printing the note,
/// or `Err(message)` to fail, when `required` (the value of the variable
/// `var`) is set to anything but empty or `0`. `what`: the tests, in words.
pub fn skip_verdict(
    var: &str,
    required: Option<&OsStr>,
    what: &str,
    why: &str,
) -> Result<String, String> {
    match required {
        Some(v) if !v.is_empty() && v != "0" => Err(format!(
            "{var}={} requires {what} to run, but {why}",
            v.to_string_lossy()
        )),
        _ => Ok(format!(
            "skipped {what}: {why} (set {var}=1 to make this a failure)\n"
        )),
    }
}

/// Fails under `var`, otherwise reports the skip on stderr.
pub fn skip(var: &str, what: &str, why: &str) {
    match skip_verdict(var, std::env::var_os(var).as_deref(), what, why) {
        Err(failure) => panic!("{failure}"),
        Ok(note) => {
            if let Err(e) = std::io::stderr().write_all(note.as_bytes()) {
                panic!("cannot report the skip ({why}): {e}");
            }
        }
    }
}

/// Checks [`skip_verdict`] for `var`.
pub fn check_verdicts(var: &str) {
    let why = "the tool is not installed";
    for unset in [None, Some(OsStr::new("")), Some(OsStr::new("0"))] {
        let note = skip_verdict(var, unset, "the tests", why).expect("not required: skip");
        assert!(
            note.starts_with("skipped the tests: the tool is not installed"),
            "{note}"
        );
    }
    for set in ["1", "yes"] {
        let failure =
            skip_verdict(var, Some(OsStr::new(set)), "the tests", why).expect_err("required: fail");
        assert!(
            failure.contains(&format!("{var}={set}")) && failure.contains(why),
            "{failure}"
        );
    }
}
