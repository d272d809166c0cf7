//! Fuzz target `budget`: see `ibl_fuzz::budget`. The counting allocator measures what each
//! decode allocates against the budget.
#![no_main]

#[global_allocator]
static ALLOC: ibl_fuzz::Counting = ibl_fuzz::Counting;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    ibl_fuzz::init();
    ibl_fuzz::budget(data)
});
