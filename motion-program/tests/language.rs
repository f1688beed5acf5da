//! The motion language: every instruction, every error path (line, column, what was
//! expected), the commands a program streams (loops unrolled), and a parser that never panics
//! on any bytes.

use motion_program::{CellSpec, Op, Program, Space, parse};
use proptest::prelude::*;
use shm_schema::{CommandKind, MotionCommandV2};

/// The default Gantry UBA cell: x, y, theta, and its IO.
fn gantry() -> CellSpec {
    let mut c = CellSpec::cartesian(&[("x", "mm"), ("y", "mm"), ("theta", "deg")]);
    c.inputs = vec![
        ("estop_ok".into(), 0),
        ("gripper_closed".into(), 2),
        ("part_present".into(), 3),
    ];
    c.outputs = vec![("gripper".into(), 1), ("cycle_lamp".into(), 4)];
    c
}

fn ok(src: &str) -> Program {
    parse(src.as_bytes(), &gantry()).unwrap_or_else(|e| panic!("{src:?}: {e}"))
}

const TRIANGLE: &str = "MOVE(40,40,0) // X = 40, Y = 40, θ = 0\nMOVE(140,40,0)\nMOVE(90,126,0)\nMOVE(40,40,0)\nSTOP\nEND\n";

const PICK_AND_PLACE: &str = "\
// pick at P1, place at P2, for ever
P1 = (140, 40, 0)
P2 = (40, 126, 90)
SPEED(80)
REPEAT
  WAIT(part_present, 1, 30)
  MOVE(P1)
  STOP
  OUT(gripper, 1)
  WAIT(gripper_closed, 1, 2.0)
  MOVEJ(P2, T=6)
  STOP
  OUT(gripper, 0)
  DELAY(0.25)
ENDREPEAT
END
";

#[test]
fn parses_the_seed_triangle() {
    let p = ok(TRIANGLE);
    assert_eq!(p.instructions.len(), 6);
    assert!(
        matches!(p.instructions[2].op, Op::Move { space: Space::Cartesian, target, .. } if target[..3] == [90.0, 126.0, 0.0])
    );
    assert_eq!(p.instructions[4].op, Op::Stop);
    assert_eq!((p.instructions[5].line, p.instructions[5].col), (6, 1));
    assert!(!p.forever());
}

#[test]
fn accepts_user_time_blank_lines_comments_and_lower_case() {
    let p = ok("\n  // header\nmove( 1.5 , -2e1, +3 , T = 2.5 ) // c\nend\n// after\n");
    match &p.instructions[0].op {
        Op::Move {
            target,
            cols,
            user_time_s,
            ..
        } => {
            assert_eq!(target[..3], [1.5, -20.0, 3.0]);
            assert_eq!(cols[..3], [7, 13, 19]);
            assert_eq!(*user_time_s, Some(2.5));
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(p.instructions[0].line, 3);
}

#[test]
fn every_instruction_of_a_pick_and_place_program() {
    let p = ok(PICK_AND_PLACE);
    assert!(p.forever());
    let [speed, repeat, end] = &p.instructions[..] else {
        panic!("{:?}", p.instructions)
    };
    assert_eq!(speed.op, Op::Speed { percent: 80.0 });
    assert_eq!(end.op, Op::End);
    let Op::Repeat { count: None, body } = &repeat.op else {
        panic!("{repeat:?}")
    };
    assert_eq!((repeat.line, repeat.col), (5, 1));
    let ops: Vec<&Op> = body.iter().map(|i| &i.op).collect();
    assert_eq!(
        ops[0],
        &Op::Wait {
            io: 3,
            value: true,
            timeout_s: Some(30.0)
        }
    );
    assert!(
        matches!(ops[1], Op::Move { space: Space::Cartesian, target, cols, user_time_s: None }
            if target[..3] == [140.0, 40.0, 0.0] && cols[..3] == [8, 8, 8])
    );
    assert_eq!(ops[3], &Op::Out { io: 1, value: true });
    assert!(
        matches!(ops[5], Op::Move { space: Space::Joint, target, user_time_s: Some(6.0), .. }
            if target[..3] == [40.0, 126.0, 90.0])
    );
    assert_eq!(ops[8], &Op::Delay { seconds: 0.25 });
}

fn kinds(cmds: &[MotionCommandV2]) -> Vec<CommandKind> {
    cmds.iter()
        .map(|c| CommandKind::from_wire(c.kind).expect("kind"))
        .collect()
}

#[test]
fn loops_unroll_into_numbered_commands_as_they_are_drawn() {
    let p = ok(
        "REPEAT 2\n MOVE(1,1,0)\n REPEAT 3\n  DELAY(1)\n ENDREPEAT\nENDREPEAT\nOUT(gripper, 1)\nEND",
    );
    let cmds: Vec<MotionCommandV2> = p.commands(7).collect();
    use CommandKind::*;
    assert_eq!(
        kinds(&cmds),
        [
            Move, Delay, Delay, Delay, Move, Delay, Delay, Delay, Out, End
        ]
    );
    assert!(cmds.iter().enumerate().all(|(i, c)| c.seq == i as u64 + 1));
    assert!(cmds.iter().all(|c| c.program_id == 7));
    assert_eq!(cmds[1].line, 4);
    assert_eq!((cmds[8].io, cmds[8].value), (1, 1));
    // A program that runs for ever streams for ever, iteration by iteration.
    let p = ok(PICK_AND_PLACE);
    let mut it = p.commands(1);
    let first: Vec<MotionCommandV2> = it.by_ref().take(1 + 9 * 1000).collect();
    assert_eq!(first.len(), 9001);
    assert_eq!(it.iterations(), vec![1000]);
    assert_eq!(CommandKind::from_wire(first[0].kind), Some(Speed));
    assert!((first[0].speed - 0.8).abs() < 1e-12);
    assert_eq!(CommandKind::from_wire(first[9000].kind), Some(Delay));
    // A count of zero never comes from the parser; an empty body never either.
}

#[test]
fn iterations_begun_and_passed_over_keep_the_stream_as_drawn_whole() {
    use motion_program::IterationStart;
    let src = "MOVE(1,1,0)\nREPEAT 4\n MOVE(2,1,0)\n REPEAT 5\n  DELAY(1)\n  MOVE(3,1,0)\n ENDREPEAT\n \
               OUT(gripper, 1)\nENDREPEAT\nMOVE(4,1,0)\nEND";
    let p = std::sync::Arc::new(ok(src));
    let whole: Vec<MotionCommandV2> = motion_program::Commands::new(p.clone(), 1).collect();
    assert_eq!(whole.len(), 1 + 4 * (1 + 5 * 2 + 1) + 2);
    // The commands that begin an iteration say which: the outer loop's with its MOVE, the
    // inner loop's (run again in each outer iteration: another instance) with its DELAY.
    let mut it = motion_program::Commands::new(p.clone(), 1);
    let mut begun = Vec::new();
    for _ in 0..15 {
        let c = it.next().expect("a command");
        begun.extend(it.iterations_begun().map(|b| (c.seq, b)));
    }
    let at = |depth, instance, iteration| IterationStart {
        depth,
        instance,
        iteration,
    };
    assert_eq!(
        begun,
        [
            (2, at(1, 1, 1)),
            (3, at(2, 2, 1)),
            (5, at(2, 2, 2)),
            (7, at(2, 2, 3)),
            (9, at(2, 2, 4)),
            (11, at(2, 2, 5)),
            (14, at(1, 1, 2)),
            (15, at(2, 3, 1)),
        ]
    );
    assert_eq!(it.per_iteration(1), Some(12));
    assert_eq!(it.per_iteration(2), Some(2));
    // Passing over iterations: what follows is what drawing them would have given next.
    assert_eq!(it.iterations_left(1, 1), Some(2));
    assert_eq!(it.iterations_left(1, 7), None, "another run of the loop");
    assert_eq!(it.iterations_left(2, 3), Some(4));
    assert_eq!(it.skip_iterations(2, 5), None, "only 4 are left");
    assert_eq!(it.skip_iterations(2, 3), Some(6));
    assert_eq!(it.skip_iterations(1, 2), Some(24));
    assert_eq!(it.iterations_left(1, 1), Some(0));
    let rest: Vec<MotionCommandV2> = it.collect();
    assert_eq!(rest[..], whole[15 + 6 + 24..]);
}

/// The program and the `line:column: message` start it must fail with.
fn check(src: &str, expected: &str) {
    let e = parse(src.as_bytes(), &gantry()).expect_err(src);
    let got = format!("{}:{}: {}", e.line, e.col, e.message);
    assert!(
        got.starts_with(expected),
        "for {src:?}\n got: {got}\nwant: {expected}"
    );
}

#[test]
fn errors_name_line_and_column_and_what_was_expected() {
    let cases: &[(&str, &str)] = &[
        (
            "MOVE(1,2)\nEND",
            "1:9: MOVE has 2 coordinates; the cell has 3 (x, y, theta)",
        ),
        (
            "MOVE(1,2,3,4)\nEND",
            "1:12: MOVE has more than 3 coordinates",
        ),
        ("MOVE(1,2;3)\nEND", "1:9: expected ',' or ')', found ';'"),
        ("MOVE(1,%,3)\nEND", "1:8: expected y (2 of 3), found '%'"),
        (
            "MOVE(1,2,3",
            "1:11: expected ',' or ')', found the end of the line",
        ),
        ("MOVE 1,2,3)\nEND", "1:6: expected '(' after MOVE"),
        (
            "MOVE(1,2,3) STOP\nEND",
            "1:13: unexpected 'S' after the instruction",
        ),
        ("\n  JUMP(1,2,3)\nEND", "2:3: unknown instruction \"JUMP\""),
        ("MOVE(1,2,3)\n", "2:1: the program has no END"),
        ("END\nMOVE(1,2,3)", "2:1: instruction after END (line 1)"),
        (
            "MOVE(1,2,3, T=0)\nEND",
            "1:15: the segment time T (s) = 0 must be above 0 and at most 3600",
        ),
        (
            "MOVE(1,2,3, T=1e9)\nEND",
            "1:15: the segment time T (s) = 1000000000 must be above 0 and at most 3600",
        ),
        (
            "MOVE(1,2, T=1)\nEND",
            "1:11: MOVE has 2 coordinates before T=",
        ),
        ("MOVE(1,2,1e999)\nEND", "1:10: \"1e999\" is not a number"),
        ("MOVE(1,2,--3)\nEND", "1:10: \"--3\" is not a number"),
        ("(1,2,3)\nEND", "1:1: expected MOVE, MOVEJ"),
        ("MOVE(Q)\nEND", "1:6: no position called \"Q\" is defined"),
        (
            "P = (1, 2)\nMOVE(P)\nEND",
            "2:6: P (line 1) has 2 values; MOVE needs 3 coordinates (x, y, theta)",
        ),
        (
            "P = (1,2,3)\nP = (1,2,3)\nEND",
            "2:1: position P is defined twice (first on line 1)",
        ),
        ("move = (1,2,3)\nEND", "1:1: move is a keyword"),
        (
            "gripper = (1,2,3)\nEND",
            "1:1: gripper is an IO of the cell",
        ),
        (
            "OUT(part_present, 1)\nEND",
            "1:5: part_present is an input, not an output",
        ),
        (
            "OUT(grip, 1)\nEND",
            "1:5: the cell has no output called \"grip\"; its outputs: gripper, cycle_lamp",
        ),
        ("OUT(gripper, 2)\nEND", "1:14: expected 0 or 1, found \"2\""),
        ("OUT(gripper 1)\nEND", "1:13: expected ',' then the value"),
        (
            "WAIT(gripper, 1)\nEND",
            "1:6: gripper is an output, not an input",
        ),
        (
            "WAIT(part_present, 1, 0)\nEND",
            "1:23: the timeout (s) = 0 must be at least 0.001",
        ),
        (
            "DELAY(-1)\nEND",
            "1:7: the delay (s) = -1 must be at least 0 and at most 86400",
        ),
        (
            "SPEED(0.5)\nEND",
            "1:7: the speed (percent of vmax) = 0.5 must be at least 1 and at most 100",
        ),
        ("SPEED(150)\nEND", "1:7: the speed (percent of vmax) = 150"),
        (
            "REPEAT 0\nMOVE(1,2,3)\nENDREPEAT\nEND",
            "1:8: expected a count 1..=1000000",
        ),
        (
            "REPEAT 2.5\nMOVE(1,2,3)\nENDREPEAT\nEND",
            "1:8: expected a count",
        ),
        (
            "REPEAT 2\nMOVE(1,2,3)\nEND",
            "3:1: END inside the REPEAT of line 1",
        ),
        (
            "REPEAT 2\nMOVE(1,2,3)\n",
            "1:1: this REPEAT has no ENDREPEAT",
        ),
        ("ENDREPEAT\nEND", "1:1: ENDREPEAT without a REPEAT"),
        (
            "REPEAT\nOUT(gripper, 1)\nENDREPEAT\nEND",
            "1:1: this REPEAT's body neither moves nor waits",
        ),
        (
            "REPEAT\nSTOP\nENDREPEAT\nEND",
            "1:1: this REPEAT's body neither moves nor waits",
        ),
        (
            "REPEAT\nMOVE(1,2,3)\nENDREPEAT\nMOVE(1,2,3)\nEND",
            "4:1: unreachable: the REPEAT without a count on line 1 never ends",
        ),
        (
            "MOVEJ(1,2)\nEND",
            "1:10: MOVEJ has 2 joints; the cell has 3 (x, y, theta)",
        ),
        (
            &format!("MOVE({},2,3)\nEND", "9".repeat(400)),
            "1:6: \"999999999999999999999999…\" is not a number",
        ),
        (
            &format!("{}(1)\nEND", "Z".repeat(100)),
            "1:1: unknown instruction \"ZZZZZZZZZZZZZZZZZZZZZZZZ…\"",
        ),
    ];
    for (src, want) in cases {
        check(src, want);
    }
    let nested = "REPEAT 2\n".repeat(10) + "MOVE(1,2,3)\n" + &"ENDREPEAT\n".repeat(10) + "END";
    check(&nested, "9:1: REPEAT nested more than 8 deep");
}

#[test]
fn bytes_that_are_not_text_are_refused_with_their_place() {
    let e = parse(b"MOVE(1,2,3)\nMOVE(\xff,2,3)\nEND", &gantry()).expect_err("not UTF-8");
    assert_eq!((e.line, e.col), (2, 6), "{e}");
    assert!(e.message.contains("0xFF is not UTF-8 text"), "{e}");
    let big = vec![b' '; motion_program::MAX_SOURCE_BYTES + 1];
    let e = parse(&big, &gantry()).expect_err("too big");
    assert!(e.message.contains("at most 1048576"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, ..ProptestConfig::default() })]

    /// Any bytes: an error or a program, never a panic.
    #[test]
    fn the_parser_never_panics_on_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = parse(&bytes, &gantry());
    }

    /// A valid program with one byte replaced or inserted: never a panic, and whatever is
    /// accepted streams commands that end in END (or run for ever).
    #[test]
    fn mutated_programs_never_panic(at in 0usize..400, byte in any::<u8>(), insert in any::<bool>()) {
        let mut src = PICK_AND_PLACE.as_bytes().to_vec();
        let at = at % src.len();
        if insert { src.insert(at, byte) } else { src[at] = byte }
        if let Ok(p) = parse(&src, &gantry()) {
            let n = p.commands(1).take(10_000).count();
            prop_assert!(n > 0);
        }
    }
}
