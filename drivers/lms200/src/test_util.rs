//! Helpers shared by the crate's unit tests.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure

/// Parses a space-separated hex string as written in the protocol notes.
pub(crate) fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace()
        .map(|pair| u8::from_str_radix(pair, 16).unwrap())
        .collect()
}
