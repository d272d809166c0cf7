//! Fuzz target `ktx1`: the KTX 1.1 reader (see `ibl_fuzz::container`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::container("ktx1", data)
});
