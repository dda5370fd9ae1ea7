mod common;
use common::*;
use verilator_tb::isa::{self, reg::*};

#[test]
fn add_and_exit() {
    let mut p = Prog::new();
    p.li(A0, 40).li(A1, 2).i(isa::add(A2, A0, A1));
    p.exit_pass();
    let (run, _) = run_pass(&p);
    assert_eq!(run.hart.x[A2 as usize], 42);
}
