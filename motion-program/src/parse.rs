//! Line-by-line parser of the motion language.

use crate::{Instruction, Op, Program, ProgramError};
use shm_schema::MAX_AXES;

/// Parses `src` for a cell with `axes` axes.
pub fn parse(src: &str, axes: usize) -> Result<Program, ProgramError> {
    assert!((1..=MAX_AXES).contains(&axes), "axes out of range");
    let mut instructions = Vec::new();
    let mut end_seen: Option<u32> = None;
    let mut last_line = 0u32;
    for (idx, raw) in src.lines().enumerate() {
        let line = idx as u32 + 1;
        last_line = line;
        let mut cur = Cursor {
            text: raw,
            pos: 0,
            line,
        };
        cur.skip_ws();
        if cur.at_end_of_statement() {
            continue;
        }
        if let Some(end_line) = end_seen {
            return Err(cur.error(format!(
                "instruction after END (line {end_line}); only comments may follow END"
            )));
        }
        let col = cur.col();
        let word = cur.word();
        let op = match word.to_ascii_uppercase().as_str() {
            "MOVE" => parse_move(&mut cur, axes)?,
            "STOP" => Op::Stop,
            "END" => {
                end_seen = Some(line);
                Op::End
            }
            "" => {
                return Err(cur.error(format!("expected MOVE, STOP or END, found {}", cur.found())));
            }
            other => {
                return Err(ProgramError {
                    line,
                    col,
                    message: format!("unknown instruction {other:?}; expected MOVE, STOP or END"),
                });
            }
        };
        cur.skip_ws();
        if !cur.at_end_of_statement() {
            return Err(cur.error(format!("unexpected {} after the instruction", cur.found())));
        }
        instructions.push(Instruction { line, col, op });
    }
    if end_seen.is_none() {
        return Err(ProgramError {
            line: last_line + 1,
            col: 1,
            message: "the program has no END".into(),
        });
    }
    Ok(Program { axes, instructions })
}

fn parse_move(cur: &mut Cursor<'_>, axes: usize) -> Result<Op, ProgramError> {
    let mut target = [0.0; MAX_AXES];
    let mut cols = [0u32; MAX_AXES];
    let mut user_time_s = None;
    cur.skip_ws();
    cur.expect('(', "'(' after MOVE")?;
    let mut n = 0usize;
    loop {
        cur.skip_ws();
        let col = cur.col();
        if cur.peek_named_time() {
            if n < axes {
                return Err(cur.error(format!(
                    "MOVE has {n} coordinate(s) before T=, the cell has {axes} axes"
                )));
            }
            cur.pos += 1; // 'T' or 't'
            cur.skip_ws();
            cur.expect('=', "'=' after T")?;
            cur.skip_ws();
            let tcol = cur.col();
            let t = cur.number("the segment time T (s)")?;
            if t <= 0.0 {
                return Err(ProgramError {
                    line: cur.line,
                    col: tcol,
                    message: format!("segment time T = {t} s must be positive"),
                });
            }
            user_time_s = Some(t);
            cur.skip_ws();
            cur.expect(')', "')' after T=<seconds>")?;
            break;
        }
        let v = cur.number(&format!("coordinate {} of {axes}", n + 1))?;
        if n >= axes {
            return Err(ProgramError {
                line: cur.line,
                col,
                message: format!("MOVE has more than {axes} coordinates; the cell has {axes} axes"),
            });
        }
        target[n] = v;
        cols[n] = col;
        n += 1;
        cur.skip_ws();
        match cur.peek() {
            Some(',') => cur.pos += 1,
            Some(')') => {
                cur.pos += 1;
                if n < axes {
                    return Err(cur.error_at(
                        cur.col() - 1,
                        format!("MOVE has {n} coordinate(s), the cell has {axes} axes"),
                    ));
                }
                break;
            }
            _ => return Err(cur.error(format!("expected ',' or ')', found {}", cur.found()))),
        }
    }
    Ok(Op::Move {
        target,
        cols,
        user_time_s,
    })
}

struct Cursor<'a> {
    text: &'a str,
    pos: usize,
    line: u32,
}

impl Cursor<'_> {
    fn rest(&self) -> &str {
        &self.text[self.pos..]
    }

    fn peek(&self) -> Option<char> {
        self.rest().chars().next()
    }

    fn col(&self) -> u32 {
        self.text[..self.pos].chars().count() as u32 + 1
    }

    fn skip_ws(&mut self) {
        let trimmed = self.rest().trim_start();
        self.pos = self.text.len() - trimmed.len();
    }

    fn at_end_of_statement(&self) -> bool {
        let r = self.rest();
        r.is_empty() || r.starts_with("//")
    }

    fn word(&mut self) -> &str {
        let start = self.pos;
        let len = self
            .rest()
            .find(|c: char| !c.is_ascii_alphabetic())
            .unwrap_or(self.rest().len());
        self.pos += len;
        &self.text[start..self.pos]
    }

    fn peek_named_time(&self) -> bool {
        let mut it = self.rest().chars();
        matches!(it.next(), Some('T' | 't')) && it.find(|c| !c.is_whitespace()) == Some('=')
    }

    fn found(&self) -> String {
        match self.peek() {
            None => "the end of the line".into(),
            Some(_) if self.rest().starts_with("//") => "a comment".into(),
            Some(c) => format!("{c:?}"),
        }
    }

    fn expect(&mut self, c: char, what: &str) -> Result<(), ProgramError> {
        if self.peek() == Some(c) {
            self.pos += c.len_utf8();
            Ok(())
        } else {
            Err(self.error(format!("expected {what}, found {}", self.found())))
        }
    }

    fn number(&mut self, what: &str) -> Result<f64, ProgramError> {
        let len = self
            .rest()
            .find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'e' | 'E')))
            .unwrap_or(self.rest().len());
        let tok = &self.rest()[..len];
        match tok.parse::<f64>() {
            Ok(v) if v.is_finite() => {
                self.pos += len;
                Ok(v)
            }
            _ if tok.is_empty() => {
                Err(self.error(format!("expected {what}, found {}", self.found())))
            }
            _ => Err(self.error(format!("{tok:?} is not a number (expected {what})"))),
        }
    }

    fn error(&self, message: String) -> ProgramError {
        self.error_at(self.col(), message)
    }

    fn error_at(&self, col: u32, message: String) -> ProgramError {
        ProgramError {
            line: self.line,
            col,
            message,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRIANGLE: &str = "MOVE(40,40,0) // X = 40, Y = 40, θ = 0\nMOVE(140,40,0)\nMOVE(90,126,0)\nMOVE(40,40,0)\nSTOP\nEND\n";

    #[test]
    fn parses_the_seed_triangle() {
        let p = parse(TRIANGLE, 3).expect("parses");
        assert_eq!(p.instructions.len(), 6);
        assert!(
            matches!(p.instructions[2].op, Op::Move { target, .. } if target[..3] == [90.0, 126.0, 0.0])
        );
        assert_eq!(p.instructions[4].op, Op::Stop);
        assert_eq!(
            p.instructions[5],
            Instruction {
                line: 6,
                col: 1,
                op: Op::End
            }
        );
    }

    #[test]
    fn accepts_user_time_blank_lines_comments_and_lower_case() {
        let p = parse(
            "\n  // header\nmove( 1.5 , -2e1, +3 , T = 2.5 ) // c\nend\n// after\n",
            3,
        )
        .expect("parses");
        match p.instructions[0].op {
            Op::Move {
                target,
                cols,
                user_time_s,
            } => {
                assert_eq!(target[..3], [1.5, -20.0, 3.0]);
                assert_eq!(cols[..3], [7, 13, 19]);
                assert_eq!(user_time_s, Some(2.5));
            }
            ref other => panic!("{other:?}"),
        }
        assert_eq!(p.instructions[0].line, 3);
    }

    /// Data-driven: the program, and the `line:column: message` start it must fail with.
    fn check(src: &str, expected: &str) {
        let e = parse(src, 3).expect_err(src);
        let got = format!("{}:{}: {}", e.line, e.col, e.message);
        assert!(
            got.starts_with(expected),
            "for {src:?}\n got: {got}\nwant: {expected}"
        );
    }

    #[test]
    fn errors_name_line_and_column() {
        check(
            "MOVE(1,2)\nEND",
            "1:9: MOVE has 2 coordinate(s), the cell has 3 axes",
        );
        check(
            "MOVE(1,2,3,4)\nEND",
            "1:12: MOVE has more than 3 coordinates",
        );
        check("MOVE(1,2;3)\nEND", "1:9: expected ',' or ')', found ';'");
        check(
            "MOVE(1,x,3)\nEND",
            "1:8: expected coordinate 2 of 3, found 'x'",
        );
        check(
            "MOVE(1,2,3",
            "1:11: expected ',' or ')', found the end of the line",
        );
        check("MOVE 1,2,3)\nEND", "1:6: expected '(' after MOVE");
        check(
            "MOVE(1,2,3) STOP\nEND",
            "1:13: unexpected 'S' after the instruction",
        );
        check("\n  JUMP(1,2,3)\nEND", "2:3: unknown instruction \"JUMP\"");
        check("MOVE(1,2,3)\n", "2:1: the program has no END");
        check("END\nMOVE(1,2,3)", "2:1: instruction after END (line 1)");
        check(
            "MOVE(1,2,3, T=0)\nEND",
            "1:15: segment time T = 0 s must be positive",
        );
        check(
            "MOVE(1,2, T=1)\nEND",
            "1:11: MOVE has 2 coordinate(s) before T=",
        );
        check("MOVE(1,2,1e999)\nEND", "1:10: \"1e999\" is not a number");
        check("MOVE(1,2,--3)\nEND", "1:10: \"--3\" is not a number");
        check("(1,2,3)\nEND", "1:1: expected MOVE, STOP or END, found '('");
    }

    #[test]
    fn limits_are_checked_with_the_coordinate_column() {
        let axes = ["x", "y", "theta"].map(|n| crate::AxisSpec {
            name: n.into(),
            unit: "mm".into(),
            min: 0.0,
            max: 100.0,
            vmax: 10.0,
        });
        let p = parse("MOVE(1,2,3)\nMOVE(5, 150, 3)\nEND", 3).expect("parses");
        let e = p.check_limits(&axes).expect_err("out of limits");
        assert_eq!((e.line, e.col), (2, 9));
        assert!(
            e.message
                .starts_with("y = 150 mm is outside the axis limits 0 .. 100 mm"),
            "{e}"
        );
        assert!(
            parse("MOVE(0,100,50)\nEND", 3)
                .expect("parses")
                .check_limits(&axes)
                .is_ok()
        );
    }
}
