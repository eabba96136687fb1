#![no_main]
//! Fuzzes `scene::fuzz_entry::nerfies_json` (see that module for what the input holds).

libfuzzer_sys::fuzz_target!(|data: &[u8]| segsplat_fuzz::scene::fuzz_entry::nerfies_json(data));
