//! Line-by-line parser of the motion language (grammar in `docs/language.md`).

use crate::{
    CellSpec, Instruction, MAX_NAME_LEN, MAX_NESTING, MAX_REPEAT, MAX_SEGMENT_TIME_S,
    MAX_SOURCE_BYTES, MAX_WAIT_S, Op, Program, ProgramError, Space, cut,
};
use shm_schema::MAX_AXES;
use std::collections::HashMap;

/// The keywords (case-insensitive); none may name a position.
const KEYWORDS: [&str; 11] = [
    "MOVE",
    "MOVEJ",
    "STOP",
    "END",
    "OUT",
    "WAIT",
    "DELAY",
    "SPEED",
    "REPEAT",
    "ENDREPEAT",
    "T",
];

/// The shortest `WAIT` timeout (s).
const MIN_TIMEOUT_S: f64 = 0.001;

const EXPECTED: &str =
    "MOVE, MOVEJ, STOP, END, OUT, WAIT, DELAY, SPEED, REPEAT, ENDREPEAT or NAME = (…)";

/// Parses `src` (the bytes of a program file) for a cell described by `cell`. Never panics.
pub fn parse(src: &[u8], cell: &CellSpec) -> Result<Program, ProgramError> {
    let whole = |message: String| ProgramError {
        line: 1,
        col: 1,
        message,
    };
    if src.len() > MAX_SOURCE_BYTES {
        return Err(whole(format!(
            "the program is {} bytes; at most {MAX_SOURCE_BYTES} are accepted",
            src.len()
        )));
    }
    let text = match std::str::from_utf8(src) {
        Ok(t) => t,
        Err(e) => {
            let at = e.valid_up_to();
            let before = String::from_utf8_lossy(&src[..at]);
            let line = before.matches('\n').count() as u32 + 1;
            let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) as u32 + 1;
            return Err(ProgramError {
                line,
                col,
                message: format!(
                    "byte 0x{:02X} is not UTF-8 text: a program is a text file",
                    src[at]
                ),
            });
        }
    };
    for (what, n) in [
        ("coordinates", cell.coords.len()),
        ("joints", cell.joints.len()),
    ] {
        if !(1..=MAX_AXES).contains(&n) {
            return Err(whole(format!(
                "the cell has {n} {what}; 1..={MAX_AXES} are supported"
            )));
        }
    }
    Parser {
        cell,
        positions: HashMap::new(),
        stack: vec![Block {
            body: Vec::new(),
            opened: None,
        }],
        end: None,
        forever_closed: None,
        last_line: 0,
    }
    .run(text)
}

/// A body being filled: the program's, or a `REPEAT`'s (with its line, column and count).
struct Block {
    body: Vec<Instruction>,
    opened: Option<(u32, u32, Option<u32>)>,
}

struct Parser<'c> {
    cell: &'c CellSpec,
    /// Named positions: values, their count and the line they were defined on.
    positions: HashMap<String, (Vec<f64>, u32)>,
    stack: Vec<Block>,
    end: Option<u32>,
    /// The line of a `REPEAT` for ever that has been closed: nothing but `END` may follow.
    forever_closed: Option<u32>,
    last_line: u32,
}

impl Parser<'_> {
    fn run(mut self, text: &str) -> Result<Program, ProgramError> {
        for (idx, raw) in text.lines().enumerate() {
            let line = idx as u32 + 1;
            self.last_line = line;
            let mut cur = Cursor {
                text: raw,
                pos: 0,
                line,
            };
            cur.skip_ws();
            if cur.at_end_of_statement() {
                continue;
            }
            if let Some(end_line) = self.end {
                return Err(cur.error(format!(
                    "instruction after END (line {end_line}); only comments may follow END"
                )));
            }
            self.statement(&mut cur)?;
            cur.skip_ws();
            if !cur.at_end_of_statement() {
                return Err(cur.error(format!("unexpected {} after the instruction", cur.found())));
            }
        }
        if let Some(Block {
            opened: Some((l, c, _)),
            ..
        }) = self.stack.last()
        {
            return Err(ProgramError {
                line: *l,
                col: *c,
                message: "this REPEAT has no ENDREPEAT".into(),
            });
        }
        if self.end.is_none() {
            return Err(ProgramError {
                line: self.last_line + 1,
                col: 1,
                message: "the program has no END".into(),
            });
        }
        let body = self.stack.pop().map(|b| b.body).unwrap_or_default();
        Ok(Program {
            coords: self.cell.coords.len(),
            joints: self.cell.joints.len(),
            instructions: body,
        })
    }

    fn push(&mut self, ins: Instruction) {
        if let Some(b) = self.stack.last_mut() {
            b.body.push(ins);
        }
    }

    fn statement(&mut self, cur: &mut Cursor<'_>) -> Result<(), ProgramError> {
        let (line, col) = (cur.line, cur.col());
        let word = cur.word();
        if word.is_empty() {
            return Err(cur.error(format!("expected {EXPECTED}, found {}", cur.found())));
        }
        let upper = word.to_ascii_uppercase();
        let save = cur.pos;
        cur.skip_ws();
        let defines = cur.peek() == Some('=');
        cur.pos = save;
        if let Some(l) = self.forever_closed.filter(|_| upper != "END") {
            return Err(ProgramError {
                line,
                col,
                message: format!(
                    "unreachable: the REPEAT without a count on line {l} never ends; only END may follow it"
                ),
            });
        }
        if defines {
            cur.skip_ws();
            cur.pos += 1;
            return self.define(cur, word, line, col);
        }
        let op = match upper.as_str() {
            "MOVE" => self.parse_move(cur, Space::Cartesian)?,
            "MOVEJ" => self.parse_move(cur, Space::Joint)?,
            "STOP" => Op::Stop,
            "END" => {
                if let Some(Block {
                    opened: Some((l, _, _)),
                    ..
                }) = self.stack.last()
                {
                    return Err(ProgramError {
                        line,
                        col,
                        message: format!("END inside the REPEAT of line {l}; ENDREPEAT first"),
                    });
                }
                self.end = Some(line);
                Op::End
            }
            "OUT" => {
                cur.open("OUT")?;
                let io = self.io(cur, true)?;
                cur.comma("the value, 0 or 1")?;
                let value = cur.bit()?;
                cur.close("the value")?;
                Op::Out { io, value }
            }
            "WAIT" => {
                cur.open("WAIT")?;
                let io = self.io(cur, false)?;
                cur.comma("the value, 0 or 1")?;
                let value = cur.bit()?;
                cur.skip_ws();
                let timeout_s = if cur.peek() == Some(',') {
                    cur.pos += 1;
                    cur.skip_ws();
                    Some(cur.bounded("the timeout (s)", MIN_TIMEOUT_S, MAX_WAIT_S)?)
                } else {
                    None
                };
                cur.close("the value or the timeout")?;
                Op::Wait {
                    io,
                    value,
                    timeout_s,
                }
            }
            "DELAY" => {
                cur.open("DELAY")?;
                let seconds = cur.bounded("the delay (s)", 0.0, MAX_WAIT_S)?;
                cur.close("the delay")?;
                Op::Delay { seconds }
            }
            "SPEED" => {
                cur.open("SPEED")?;
                let percent = cur.bounded("the speed (percent of vmax)", 1.0, 100.0)?;
                cur.close("the speed")?;
                Op::Speed { percent }
            }
            "REPEAT" => {
                cur.skip_ws();
                let count = if cur.at_end_of_statement() {
                    None
                } else {
                    Some(cur.count()?)
                };
                if self.stack.len() > MAX_NESTING {
                    return Err(ProgramError {
                        line,
                        col,
                        message: format!("REPEAT nested more than {MAX_NESTING} deep"),
                    });
                }
                self.stack.push(Block {
                    body: Vec::new(),
                    opened: Some((line, col, count)),
                });
                return Ok(());
            }
            "ENDREPEAT" => {
                let Some(Block {
                    body,
                    opened: Some((l, c, count)),
                }) = self.stack.pop_if(|b| b.opened.is_some())
                else {
                    return Err(ProgramError {
                        line,
                        col,
                        message: "ENDREPEAT without a REPEAT".into(),
                    });
                };
                if !body.iter().any(|i| moves_or_waits(&i.op)) {
                    return Err(ProgramError {
                        line: l,
                        col: c,
                        message: "this REPEAT's body neither moves nor waits: \
                                  it would run without end in no time"
                            .into(),
                    });
                }
                if count.is_none() {
                    self.forever_closed = Some(l);
                }
                self.push(Instruction {
                    line: l,
                    col: c,
                    op: Op::Repeat { count, body },
                });
                return Ok(());
            }
            _ => {
                return Err(ProgramError {
                    line,
                    col,
                    message: format!(
                        "unknown instruction {:?}; expected {EXPECTED}",
                        cut(word, 24)
                    ),
                });
            }
        };
        self.push(Instruction { line, col, op });
        Ok(())
    }

    /// `NAME = (v, v, …)`.
    fn define(
        &mut self,
        cur: &mut Cursor<'_>,
        name: &str,
        line: u32,
        col: u32,
    ) -> Result<(), ProgramError> {
        if KEYWORDS.iter().any(|k| k.eq_ignore_ascii_case(name)) {
            return Err(ProgramError {
                line,
                col,
                message: format!("{name} is a keyword and cannot name a position"),
            });
        }
        if name.len() > MAX_NAME_LEN {
            return Err(ProgramError {
                line,
                col,
                message: format!(
                    "the name {:?} is longer than {MAX_NAME_LEN} characters",
                    cut(name, 24)
                ),
            });
        }
        if let Some((_, l)) = self.positions.get(name) {
            return Err(ProgramError {
                line,
                col,
                message: format!("position {name} is defined twice (first on line {l})"),
            });
        }
        if self
            .cell
            .outputs
            .iter()
            .chain(&self.cell.inputs)
            .any(|(n, _)| n == name)
        {
            return Err(ProgramError {
                line,
                col,
                message: format!("{name} is an IO of the cell and cannot name a position"),
            });
        }
        cur.skip_ws();
        cur.expect('(', "'(' to start the position's values")?;
        let mut values = Vec::new();
        loop {
            cur.skip_ws();
            if values.len() == MAX_AXES {
                return Err(cur.error(format!("a position has at most {MAX_AXES} values")));
            }
            values.push(cur.number(&format!("value {} of {name}", values.len() + 1))?);
            cur.skip_ws();
            match cur.peek() {
                Some(',') => cur.pos += 1,
                Some(')') => {
                    cur.pos += 1;
                    break;
                }
                _ => {
                    return Err(cur.error(format!("expected ',' or ')', found {}", cur.found())));
                }
            }
        }
        self.positions.insert(name.to_string(), (values, line));
        Ok(())
    }

    fn parse_move(&self, cur: &mut Cursor<'_>, space: Space) -> Result<Op, ProgramError> {
        let (kw, names) = match space {
            Space::Cartesian => ("MOVE", &self.cell.coords),
            Space::Joint => ("MOVEJ", &self.cell.joints),
        };
        let n = names.len();
        let what = match space {
            Space::Cartesian => "coordinates",
            Space::Joint => "joints",
        };
        let mut target = [0.0; MAX_AXES];
        let mut cols = [0u32; MAX_AXES];
        let mut user_time_s = None;
        cur.skip_ws();
        cur.expect('(', &format!("'(' after {kw}"))?;
        cur.skip_ws();
        let name_col = cur.col();
        let mut got = 0usize;
        if cur
            .peek()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && !cur.peek_named_time()
        {
            let name = cur.name();
            let Some((values, line)) = self.positions.get(name) else {
                return Err(cur.error_at(
                    name_col,
                    format!(
                        "no position called {:?} is defined before this line",
                        cut(name, 24)
                    ),
                ));
            };
            if values.len() != n {
                return Err(cur.error_at(
                    name_col,
                    format!(
                        "{name} (line {line}) has {} values; {kw} needs {n} {what} ({})",
                        values.len(),
                        joined(names)
                    ),
                ));
            }
            target[..n].copy_from_slice(values);
            cols[..n].fill(name_col);
            got = n;
            cur.skip_ws();
            match cur.peek() {
                Some(',') => cur.pos += 1,
                Some(')') => {
                    cur.pos += 1;
                    return Ok(Op::Move {
                        space,
                        target,
                        cols,
                        user_time_s,
                    });
                }
                _ => {
                    return Err(cur.error(format!(
                        "expected ',' or ')' after {name}, found {}",
                        cur.found()
                    )));
                }
            }
        }
        loop {
            cur.skip_ws();
            let col = cur.col();
            if cur.peek_named_time() {
                if got < n {
                    return Err(cur.error(format!(
                        "{kw} has {got} {what} before T=; the cell has {n} ({})",
                        joined(names)
                    )));
                }
                cur.pos += 1; // 'T' or 't'
                cur.skip_ws();
                cur.expect('=', "'=' after T")?;
                cur.skip_ws();
                let t = cur.bounded(
                    "the segment time T (s)",
                    f64::MIN_POSITIVE,
                    MAX_SEGMENT_TIME_S,
                )?;
                user_time_s = Some(t);
                cur.skip_ws();
                cur.expect(')', "')' after T=<seconds>")?;
                break;
            }
            if got >= n {
                return Err(cur.error(format!(
                    "{kw} has more than {n} {what}; the cell has {n} ({})",
                    joined(names)
                )));
            }
            let v = cur.number(&format!("{} ({} of {n})", names[got].0, got + 1))?;
            target[got] = v;
            cols[got] = col;
            got += 1;
            cur.skip_ws();
            match cur.peek() {
                Some(',') => cur.pos += 1,
                Some(')') => {
                    cur.pos += 1;
                    if got < n {
                        return Err(cur.error_at(
                            cur.col() - 1,
                            format!(
                                "{kw} has {got} {what}; the cell has {n} ({})",
                                joined(names)
                            ),
                        ));
                    }
                    break;
                }
                _ => {
                    return Err(cur.error(format!("expected ',' or ')', found {}", cur.found())));
                }
            }
        }
        Ok(Op::Move {
            space,
            target,
            cols,
            user_time_s,
        })
    }

    /// An IO name: an output for `OUT`, an input for `WAIT`.
    fn io(&self, cur: &mut Cursor<'_>, output: bool) -> Result<u32, ProgramError> {
        cur.skip_ws();
        let col = cur.col();
        let name = cur.name();
        let (want, other, kind) = if output {
            (&self.cell.outputs, &self.cell.inputs, "output")
        } else {
            (&self.cell.inputs, &self.cell.outputs, "input")
        };
        if name.is_empty() {
            return Err(cur.error(format!(
                "expected the name of an {kind}, found {}",
                cur.found()
            )));
        }
        if let Some((_, k)) = want.iter().find(|(n, _)| n == name) {
            return Ok(*k);
        }
        let message = if other.iter().any(|(n, _)| n == name) {
            format!(
                "{name} is an {}, not an {kind}",
                if output { "input" } else { "output" }
            )
        } else if want.is_empty() {
            format!(
                "the cell has no {kind} called {:?} (it has none: `[[io]]` in the configuration)",
                cut(name, 24)
            )
        } else {
            let names: Vec<&str> = want.iter().map(|(n, _)| n.as_str()).collect();
            format!(
                "the cell has no {kind} called {:?}; its {kind}s: {}",
                cut(name, 24),
                names.join(", ")
            )
        };
        Err(cur.error_at(col, message))
    }
}

/// True for instructions that take time: a loop of nothing else would spin.
fn moves_or_waits(op: &Op) -> bool {
    match op {
        // A STOP before any move takes no time: a body of STOPs alone could spin.
        Op::Move { .. } | Op::Wait { .. } => true,
        Op::Delay { seconds } => *seconds > 0.0,
        Op::Repeat { body, .. } => body.iter().any(|i| moves_or_waits(&i.op)),
        _ => false,
    }
}

fn joined(names: &[(String, String)]) -> String {
    names
        .iter()
        .map(|(n, _)| n.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

struct Cursor<'a> {
    text: &'a str,
    pos: usize,
    line: u32,
}

impl<'a> Cursor<'a> {
    fn rest(&self) -> &'a str {
        self.text.get(self.pos..).unwrap_or("")
    }

    fn peek(&self) -> Option<char> {
        self.rest().chars().next()
    }

    fn col(&self) -> u32 {
        self.text.get(..self.pos).map_or(0, |s| s.chars().count()) as u32 + 1
    }

    fn skip_ws(&mut self) {
        let trimmed = self.rest().trim_start();
        self.pos = self.text.len() - trimmed.len();
    }

    fn at_end_of_statement(&self) -> bool {
        let r = self.rest();
        r.is_empty() || r.starts_with("//")
    }

    /// A run of letters, digits and `_` starting with a letter or `_` (empty if none).
    fn word(&mut self) -> &'a str {
        if !self
            .peek()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        {
            return "";
        }
        self.name()
    }

    fn name(&mut self) -> &'a str {
        let start = self.pos;
        let len = self
            .rest()
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(self.rest().len());
        self.pos += len;
        self.text.get(start..self.pos).unwrap_or("")
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

    fn open(&mut self, kw: &str) -> Result<(), ProgramError> {
        self.skip_ws();
        self.expect('(', &format!("'(' after {kw}"))
    }

    fn comma(&mut self, next: &str) -> Result<(), ProgramError> {
        self.skip_ws();
        self.expect(',', &format!("',' then {next}"))?;
        self.skip_ws();
        Ok(())
    }

    fn close(&mut self, after: &str) -> Result<(), ProgramError> {
        self.skip_ws();
        self.expect(')', &format!("')' after {after}"))
    }

    fn token(&self) -> &'a str {
        let len = self
            .rest()
            .find(|c: char| !(c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '+')))
            .unwrap_or(self.rest().len());
        self.rest().get(..len).unwrap_or("")
    }

    fn number(&mut self, what: &str) -> Result<f64, ProgramError> {
        let tok = self.token();
        match tok.parse::<f64>() {
            Ok(v) if v.is_finite() => {
                self.pos += tok.len();
                Ok(v)
            }
            _ if tok.is_empty() => {
                Err(self.error(format!("expected {what}, found {}", self.found())))
            }
            _ => Err(self.error(format!(
                "{:?} is not a number (expected {what})",
                cut(tok, 24)
            ))),
        }
    }

    /// A number within `lo..=hi`.
    fn bounded(&mut self, what: &str, lo: f64, hi: f64) -> Result<f64, ProgramError> {
        let col = self.col();
        let v = self.number(what)?;
        if v < lo || v > hi {
            let lo_text = if lo == f64::MIN_POSITIVE {
                "above 0".to_string()
            } else {
                format!("at least {lo}")
            };
            return Err(self.error_at(
                col,
                format!("{what} = {v} must be {lo_text} and at most {hi}"),
            ));
        }
        Ok(v)
    }

    fn bit(&mut self) -> Result<bool, ProgramError> {
        self.skip_ws();
        match self.token() {
            "0" => {
                self.pos += 1;
                Ok(false)
            }
            "1" => {
                self.pos += 1;
                Ok(true)
            }
            "" => Err(self.error(format!("expected 0 or 1, found {}", self.found()))),
            t => Err(self.error(format!("expected 0 or 1, found {:?}", cut(t, 24)))),
        }
    }

    fn count(&mut self) -> Result<u32, ProgramError> {
        let tok = self.token();
        match tok.parse::<u32>() {
            Ok(n) if (1..=MAX_REPEAT).contains(&n) => {
                self.pos += tok.len();
                Ok(n)
            }
            _ => Err(self.error(format!(
                "expected a count 1..={MAX_REPEAT} (or nothing: for ever), found {}",
                if tok.is_empty() {
                    self.found()
                } else {
                    format!("{:?}", cut(tok, 24))
                }
            ))),
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
