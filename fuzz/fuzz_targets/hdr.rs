//! Fuzz target `hdr`: see `ibl_fuzz::hdr`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::hdr(data)
});
