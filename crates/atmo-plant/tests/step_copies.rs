//! The two copies of the step code (portable, and AVX2 + FMA where the CPU
//! has them) give the same bits, in atmo-plant alone: the benchmark's four
//! cases (hover, morphing, driving on four wheels, every effect off), 1 s
//! each, compared state by state after every step. The atmo-sim test
//! `the_avx2_step_code_gives_the_portable_code_s_trajectory_bit_for_bit`
//! does the same for every scenario in closed loop.

#[path = "../benches/support/cases.rs"]
mod cases;

#[test]
fn the_avx2_copy_steps_the_bench_cases_bit_for_bit_like_the_portable_copy() {
    for case in cases::cases() {
        let mut fast = case.plant.clone();
        let mut portable = case.plant.clone();
        if !fast.uses_avx2() {
            eprintln!("{}: this CPU runs the portable code only", case.name);
        }
        portable.use_portable_code();
        for k in 0..cases::STEPS {
            let command = (case.command)(k);
            fast.step(&command).expect("the AVX2 copy steps");
            portable.step(&command).expect("the portable copy steps");
            let (a, b) = (fast.state(), portable.state());
            let same = a
                .iter()
                .zip(b.iter())
                .all(|(x, y)| x.to_bits() == y.to_bits())
                && fast.tilt().to_bits() == portable.tilt().to_bits()
                && fast.contacts() == portable.contacts();
            assert!(same, "{}, step {k}: {a:?} against {b:?}", case.name);
        }
    }
}
