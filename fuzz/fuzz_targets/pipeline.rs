//! Fuzz target `pipeline`: see `ibl_fuzz::pipeline`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::pipeline(data)
});
