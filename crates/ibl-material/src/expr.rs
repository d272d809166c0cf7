//! A small, safe expression language for per-texel fields (`--expr "x=cos(pi*v); y=sin(pi*v)"`):
//! a recursive-descent parser compiled to a stack program. Nothing is ever executed but
//! arithmetic; every parse error names the 1-based column where parsing failed.
//!
//! Grammar (statements separated by `;`; `name = expr` assigns, a bare `expr` fills the next
//! unassigned output; helper variables may be defined and used in later statements):
//!
//! ```text
//! stmt    := [ident '='] expr
//! expr    := term (('+' | '-') term)*
//! term    := unary (('*' | '/') unary)*
//! unary   := ('-' | '+') unary | power
//! power   := primary [('^' | '**') unary]          right-associative; -2^2 = -4
//! primary := number | ident | ident '(' expr (',' expr)* ')' | '(' expr ')'
//! ```
//!
//! Constants `pi`, `tau`; functions sin cos tan asin acos atan atan2(y,x) sqrt abs pow exp
//! log(natural) floor ceil round fract sign min max (2 or more arguments) hypot mod(x,y)
//! (GLSL: x − y·floor(x/y)) clamp(x,lo,hi) mix(a,b,t) step(edge,x) smoothstep(e0,e1,x).
//! Domain errors give NaN/∞, which the caller counts and replaces.

use std::fmt;

/// A parse error at a 1-based character column of the source.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("column {column}: {message}")]
pub struct ExprError {
    /// 1-based column of the expression where the problem starts.
    pub column: usize,
    /// What is wrong there.
    pub message: String,
}

fn err<T>(column: usize, message: impl Into<String>) -> Result<T, ExprError> {
    Err(ExprError {
        column,
        message: message.into(),
    })
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Num(f64),
    Ident(String),
    Sym(&'static str),
    End,
}

#[derive(Clone, Debug)]
struct Token {
    tok: Tok,
    col: usize,
}

fn lex(src: &str) -> Result<Vec<Token>, ExprError> {
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let mut k = 0;
    while k < chars.len() {
        let c = chars[k];
        let col = k + 1;
        if c.is_whitespace() {
            k += 1;
        } else if c.is_ascii_digit()
            || (c == '.' && chars.get(k + 1).is_some_and(|d| d.is_ascii_digit()))
        {
            let start = k;
            while k < chars.len() && (chars[k].is_ascii_digit() || chars[k] == '.') {
                k += 1;
            }
            if k < chars.len() && (chars[k] == 'e' || chars[k] == 'E') {
                let mut m = k + 1;
                if m < chars.len() && (chars[m] == '+' || chars[m] == '-') {
                    m += 1;
                }
                if m < chars.len() && chars[m].is_ascii_digit() {
                    k = m;
                    while k < chars.len() && chars[k].is_ascii_digit() {
                        k += 1;
                    }
                }
            }
            let text: String = chars[start..k].iter().collect();
            match text.parse::<f64>() {
                Ok(v) => out.push(Token {
                    tok: Tok::Num(v),
                    col,
                }),
                Err(_) => return err(col, format!("malformed number '{text}'")),
            }
        } else if c.is_alphabetic() || c == '_' {
            let start = k;
            while k < chars.len() && (chars[k].is_alphanumeric() || chars[k] == '_') {
                k += 1;
            }
            out.push(Token {
                tok: Tok::Ident(chars[start..k].iter().collect()),
                col,
            });
        } else {
            let sym = match c {
                '*' if chars.get(k + 1) == Some(&'*') => "**",
                '+' => "+",
                '-' | '−' => "-",
                '*' | '×' => "*",
                '/' => "/",
                '^' => "^",
                '(' => "(",
                ')' => ")",
                ',' => ",",
                ';' => ";",
                '=' => "=",
                _ => return err(col, format!("unexpected character '{c}'")),
            };
            k += if sym == "**" { 2 } else { 1 };
            out.push(Token {
                tok: Tok::Sym(sym),
                col,
            });
        }
    }
    out.push(Token {
        tok: Tok::End,
        col: chars.len() + 1,
    });
    Ok(out)
}

type F1 = fn(f64) -> f64;
type F2 = fn(f64, f64) -> f64;
type F3 = fn(f64, f64, f64) -> f64;

#[derive(Clone, Copy)]
enum Func {
    F1(F1),
    F2(F2),
    F3(F3),
    /// min / max over 2 or more arguments.
    Fold(F2),
}

fn fract(x: f64) -> f64 {
    x - x.floor()
}
fn glsl_mod(x: f64, y: f64) -> f64 {
    x - y * (x / y).floor()
}
fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        x
    }
}
fn step(edge: f64, x: f64) -> f64 {
    if x < edge {
        0.0
    } else {
        1.0
    }
}
fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}
fn clamp3(x: f64, lo: f64, hi: f64) -> f64 {
    x.max(lo).min(hi)
}
fn mix(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// Name → (function, arity; 0 means "2 or more").
fn function(name: &str) -> Option<(Func, usize)> {
    use Func::*;
    Some(match name {
        "sin" => (F1(f64::sin), 1),
        "cos" => (F1(f64::cos), 1),
        "tan" => (F1(f64::tan), 1),
        "asin" => (F1(f64::asin), 1),
        "acos" => (F1(f64::acos), 1),
        "atan" => (F1(f64::atan), 1),
        "atan2" => (F2(f64::atan2), 2),
        "sqrt" => (F1(f64::sqrt), 1),
        "abs" => (F1(f64::abs), 1),
        "exp" => (F1(f64::exp), 1),
        "log" => (F1(f64::ln), 1),
        "floor" => (F1(f64::floor), 1),
        "ceil" => (F1(f64::ceil), 1),
        "round" => (F1(f64::round), 1),
        "fract" => (F1(fract), 1),
        "sign" => (F1(sign), 1),
        "pow" => (F2(f64::powf), 2),
        "hypot" => (F2(f64::hypot), 2),
        "mod" => (F2(glsl_mod), 2),
        "step" => (F2(step), 2),
        "min" => (Fold(f64::min), 0),
        "max" => (Fold(f64::max), 0),
        "clamp" => (F3(clamp3), 3),
        "mix" => (F3(mix), 3),
        "smoothstep" => (F3(smoothstep), 3),
        _ => return None,
    })
}

const FUNCTIONS: &str =
    "sin cos tan asin acos atan atan2 sqrt abs exp log floor ceil round fract sign pow hypot mod step min max clamp mix smoothstep";

fn constant(name: &str) -> Option<f64> {
    match name {
        "pi" => Some(std::f64::consts::PI),
        "tau" => Some(std::f64::consts::TAU),
        _ => None,
    }
}

#[derive(Clone, Copy)]
enum Op {
    Push(f64),
    Load(usize),
    Store(usize),
    Neg,
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    Call(Func, usize),
}

/// A compiled program: `inputs` occupy the first slots, then `outputs`, then helpers.
#[derive(Clone)]
pub struct Program {
    code: Vec<Op>,
    slots: usize,
    n_inputs: usize,
    n_outputs: usize,
    /// The source, for messages and summaries.
    pub source: String,
}

impl fmt::Debug for Program {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Program({:?})", self.source)
    }
}

/// Per-thread evaluation state (reused across texels: no allocation per texel).
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    env: Vec<f64>,
    stack: Vec<f64>,
}

struct Parser<'a> {
    toks: &'a [Token],
    pos: usize,
    /// Slot names; a slot is readable once assigned (inputs always are).
    names: Vec<String>,
    assigned: Vec<bool>,
    code: Vec<Op>,
    n_inputs: usize,
    depth: usize,
    /// Names assigned somewhere in the source, for a better message on early use.
    assigned_later: Vec<String>,
}

/// Bound on nesting (parentheses, unary signs), so hostile input cannot exhaust the stack.
const MAX_DEPTH: usize = 256;

impl Parser<'_> {
    fn peek(&self) -> &Token {
        &self.toks[self.pos]
    }
    fn at(&self, sym: &str) -> bool {
        matches!(&self.peek().tok, Tok::Sym(s) if *s == sym)
    }
    fn bump(&mut self) -> Token {
        let t = self.toks[self.pos].clone();
        if t.tok != Tok::End {
            self.pos += 1;
        }
        t
    }
    fn describe(t: &Token) -> String {
        match &t.tok {
            Tok::Num(v) => format!("number {v}"),
            Tok::Ident(s) => format!("'{s}'"),
            Tok::Sym(s) => format!("'{s}'"),
            Tok::End => "end of input".to_string(),
        }
    }

    fn expr(&mut self) -> Result<(), ExprError> {
        self.term()?;
        loop {
            let op = if self.at("+") {
                Op::Add
            } else if self.at("-") {
                Op::Sub
            } else {
                return Ok(());
            };
            self.bump();
            self.term()?;
            self.code.push(op);
        }
    }

    fn term(&mut self) -> Result<(), ExprError> {
        self.unary()?;
        loop {
            let op = if self.at("*") {
                Op::Mul
            } else if self.at("/") {
                Op::Div
            } else {
                return Ok(());
            };
            self.bump();
            self.unary()?;
            self.code.push(op);
        }
    }

    fn unary(&mut self) -> Result<(), ExprError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return err(
                self.peek().col,
                format!("nested more than {MAX_DEPTH} levels deep"),
            );
        }
        let r = self.unary_inner();
        self.depth -= 1;
        r
    }

    fn unary_inner(&mut self) -> Result<(), ExprError> {
        if self.at("-") {
            self.bump();
            self.unary()?;
            self.code.push(Op::Neg);
            Ok(())
        } else if self.at("+") {
            self.bump();
            self.unary()
        } else {
            self.power()
        }
    }

    fn power(&mut self) -> Result<(), ExprError> {
        self.primary()?;
        if self.at("^") || self.at("**") {
            self.bump();
            self.unary()?;
            self.code.push(Op::Pow);
        }
        Ok(())
    }

    fn primary(&mut self) -> Result<(), ExprError> {
        let t = self.bump();
        match t.tok {
            Tok::Num(v) => {
                self.code.push(Op::Push(v));
                Ok(())
            }
            Tok::Sym("(") => {
                self.expr()?;
                self.expect(")", "to close the '(' at column", t.col)
            }
            Tok::Ident(name) => {
                if self.at("(") {
                    let open = self.bump();
                    let Some((f, arity)) = function(&name) else {
                        return err(
                            t.col,
                            format!("unknown function '{name}' (known: {FUNCTIONS})"),
                        );
                    };
                    let mut n = 0;
                    if !self.at(")") {
                        loop {
                            self.expr()?;
                            n += 1;
                            if self.at(",") {
                                self.bump();
                            } else {
                                break;
                            }
                        }
                    }
                    self.expect(")", "to close the '(' at column", open.col)?;
                    let ok = if arity == 0 { n >= 2 } else { n == arity };
                    if !ok {
                        let want = if arity == 0 {
                            "2 or more arguments".to_string()
                        } else {
                            plural(arity, "argument")
                        };
                        return err(t.col, format!("{name} takes {want}, got {n}"));
                    }
                    self.code.push(Op::Call(f, n));
                    return Ok(());
                }
                if let Some(v) = constant(&name) {
                    self.code.push(Op::Push(v));
                    return Ok(());
                }
                match self.names.iter().position(|s| *s == name) {
                    Some(slot) if self.assigned[slot] => {
                        self.code.push(Op::Load(slot));
                        Ok(())
                    }
                    Some(_) => err(t.col, format!("'{name}' is used before it is assigned")),
                    None if self.assigned_later.contains(&name) => {
                        err(t.col, format!("'{name}' is used before it is assigned"))
                    }
                    None if function(&name).is_some() => {
                        err(t.col, format!("'{name}' is a function: write {name}(...)"))
                    }
                    None => {
                        let known: Vec<&str> = self.names[..self.n_inputs]
                            .iter()
                            .map(|s| s.as_str())
                            .collect();
                        err(
                            t.col,
                            format!(
                                "unknown variable '{name}' (inputs: {}, constants: pi, tau)",
                                known.join(", ")
                            ),
                        )
                    }
                }
            }
            _ => err(
                t.col,
                format!(
                    "expected a number, variable, function or '(', found {}",
                    Self::describe(&t)
                ),
            ),
        }
    }

    fn expect(&mut self, sym: &str, why: &str, col: usize) -> Result<(), ExprError> {
        if self.at(sym) {
            self.bump();
            Ok(())
        } else {
            let t = self.peek();
            err(
                t.col,
                format!("expected '{sym}' {why} {col}, found {}", Self::describe(t)),
            )
        }
    }
}

fn plural(n: usize, what: &str) -> String {
    if n == 1 {
        format!("1 {what}")
    } else {
        format!("{n} {what}s")
    }
}

/// Compiles `src` with the given input names (readable everywhere) and output names (each
/// must be assigned exactly once, by name or by position).
pub fn compile(src: &str, inputs: &[&str], outputs: &[&str]) -> Result<Program, ExprError> {
    let toks = lex(src)?;
    let assigned_later: Vec<String> = toks
        .windows(2)
        .filter_map(|w| match (&w[0].tok, &w[1].tok) {
            (Tok::Ident(n), Tok::Sym("=")) => Some(n.clone()),
            _ => None,
        })
        .collect();
    let mut names: Vec<String> = inputs
        .iter()
        .chain(outputs)
        .map(|s| s.to_string())
        .collect();
    let mut assigned: Vec<bool> = (0..names.len()).map(|k| k < inputs.len()).collect();
    let mut p = Parser {
        toks: &toks,
        pos: 0,
        names: Vec::new(),
        assigned: Vec::new(),
        code: Vec::new(),
        n_inputs: inputs.len(),
        depth: 0,
        assigned_later,
    };
    std::mem::swap(&mut p.names, &mut names);
    std::mem::swap(&mut p.assigned, &mut assigned);
    let n_fixed = inputs.len() + outputs.len();
    loop {
        while p.at(";") {
            p.bump();
        }
        if p.peek().tok == Tok::End {
            break;
        }
        // `name = expr` or a bare expression.
        let start = p.peek().clone();
        let target = match (&start.tok, &toks[p.pos + 1].tok) {
            (Tok::Ident(name), Tok::Sym("=")) => {
                p.bump();
                p.bump();
                if constant(name).is_some() {
                    return err(
                        start.col,
                        format!("'{name}' is a constant and cannot be assigned"),
                    );
                }
                if function(name).is_some() {
                    return err(
                        start.col,
                        format!("'{name}' is a function and cannot be assigned"),
                    );
                }
                match p.names.iter().position(|s| s == name) {
                    Some(slot) if slot < inputs.len() => {
                        return err(
                            start.col,
                            format!("'{name}' is an input and cannot be assigned"),
                        );
                    }
                    Some(slot) if p.assigned[slot] => {
                        return err(start.col, format!("'{name}' is assigned twice"))
                    }
                    Some(slot) => slot,
                    None => {
                        p.names.push(name.clone());
                        p.assigned.push(false);
                        p.names.len() - 1
                    }
                }
            }
            _ => match (inputs.len()..n_fixed).find(|&s| !p.assigned[s]) {
                Some(slot) => slot,
                None => {
                    return err(
                        start.col,
                        format!(
                            "unexpected extra expression: all of {} are already assigned",
                            outputs.join(", ")
                        ),
                    );
                }
            },
        };
        p.expr()?;
        p.code.push(Op::Store(target));
        p.assigned[target] = true;
        if !(p.at(";") || p.peek().tok == Tok::End) {
            let t = p.peek();
            let hint = if matches!(t.tok, Tok::Ident(_) | Tok::Num(_) | Tok::Sym("(")) {
                " (missing operator or ';'?)"
            } else {
                ""
            };
            return err(
                t.col,
                format!(
                    "expected an operator, ';' or the end, found {}{hint}",
                    Parser::describe(t)
                ),
            );
        }
    }
    let end = src.chars().count() + 1;
    if let Some(missing) = (inputs.len()..n_fixed).find(|&s| !p.assigned[s]) {
        return err(
            end,
            format!(
                "missing '{} = ...' (expected {})",
                p.names[missing],
                outputs.join(", ")
            ),
        );
    }
    let slots = p.names.len();
    Ok(Program {
        code: p.code,
        slots,
        n_inputs: inputs.len(),
        n_outputs: outputs.len(),
        source: src.to_string(),
    })
}

impl Program {
    /// Evaluates the program for one set of inputs, writing the outputs.
    pub fn eval(&self, inputs: &[f64], scratch: &mut Scratch, outputs: &mut [f64]) {
        debug_assert_eq!(inputs.len(), self.n_inputs);
        let Scratch { env, stack } = scratch;
        env.clear();
        env.resize(self.slots, 0.0);
        env[..self.n_inputs].copy_from_slice(inputs);
        stack.clear();
        for op in &self.code {
            match *op {
                Op::Push(v) => stack.push(v),
                Op::Load(s) => stack.push(env[s]),
                Op::Store(s) => env[s] = stack.pop().unwrap_or(f64::NAN),
                Op::Neg => {
                    if let Some(v) = stack.last_mut() {
                        *v = -*v;
                    }
                }
                Op::Add | Op::Sub | Op::Mul | Op::Div | Op::Pow => {
                    let b = stack.pop().unwrap_or(f64::NAN);
                    let a = stack.pop().unwrap_or(f64::NAN);
                    stack.push(match op {
                        Op::Add => a + b,
                        Op::Sub => a - b,
                        Op::Mul => a * b,
                        Op::Div => a / b,
                        _ => a.powf(b),
                    });
                }
                Op::Call(f, n) => {
                    let args = stack.split_off(stack.len() - n);
                    stack.push(match f {
                        Func::F1(f) => f(args[0]),
                        Func::F2(f) => f(args[0], args[1]),
                        Func::F3(f) => f(args[0], args[1], args[2]),
                        Func::Fold(f) => args[1..].iter().fold(args[0], |a, &b| f(a, b)),
                    });
                }
            }
        }
        outputs.copy_from_slice(&env[self.n_inputs..self.n_inputs + self.n_outputs]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eval2(src: &str, u: f64, v: f64) -> [f64; 2] {
        let p = compile(src, &["u", "v"], &["x", "y"]).unwrap();
        let mut out = [0.0; 2];
        p.eval(&[u, v], &mut Scratch::default(), &mut out);
        out
    }

    fn error(src: &str) -> ExprError {
        compile(src, &["u", "v"], &["x", "y"]).unwrap_err()
    }

    #[test]
    fn thesis_wave_and_precedence() {
        let [x, y] = eval2("x = cos(pi*v); y = sin(pi*v)", 0.3, 0.25);
        assert!(
            (x - (std::f64::consts::PI * 0.25).cos()).abs() < 1e-15
                && (y - (std::f64::consts::PI * 0.25).sin()).abs() < 1e-15
        );
        // Precedence and associativity against hand-computed values.
        let cases: [(&str, f64); 14] = [
            ("1 + 2 * 3", 7.0),
            ("(1 + 2) * 3", 9.0),
            ("2 ^ 3 ^ 2", 512.0),
            ("2 ** 3", 8.0),
            ("-2 ^ 2", -4.0),
            ("2 ^ -1", 0.5),
            ("8 / 4 / 2", 1.0),
            ("10 - 4 - 3", 3.0),
            ("--3", 3.0),
            ("+4 * -u", -2.0),
            ("1.5e1 + .5", 15.5),
            ("min(3, u, 7) + max(1, 2)", 2.5),
            ("atan2(1, 0) * 2 / pi", 1.0),
            ("mod(-1, 3) + fract(2.25) + floor(-0.5)", 1.25),
        ];
        for (src, want) in cases {
            let [x, _] = eval2(&format!("{src}; 0"), 0.5, 0.0);
            assert!((x - want).abs() < 1e-12, "{src} = {x}, want {want}");
        }
        let [x, y] = eval2("clamp(u*4, 0, 1); mix(2, 4, v) + smoothstep(0, 1, 0.5) + step(0.5, u) + pow(2, 10) + sqrt(abs(-16)) + tan(0)", 0.1, 0.5);
        assert!((x - 0.4).abs() < 1e-15 && (y - (3.0 + 0.5 + 0.0 + 1024.0 + 4.0)).abs() < 1e-12);
    }

    #[test]
    fn helpers_and_positional_outputs() {
        let [x, y] = eval2("r = hypot(u - 0.5, v - 0.5); a = atan2(v - 0.5, u - 0.5); x = -sin(a) * r; y = cos(a) * r", 1.0, 0.5);
        assert!(x.abs() < 1e-15 && (y - 0.5).abs() < 1e-15);
        let [x, y] = eval2("y = 2; 3", 0.0, 0.0);
        assert_eq!([x, y], [3.0, 2.0]);
        let [x, y] = eval2(";; u; v;", 0.25, 0.75);
        assert_eq!([x, y], [0.25, 0.75]);
    }

    #[test]
    fn errors_report_the_column() {
        let cases: [(&str, usize, &str); 16] = [
            ("x = sinn(u); y = 0", 5, "unknown function 'sinn'"),
            ("x = u +; y = 0", 8, "expected a number"),
            (
                "x = (u + 1; y = 0",
                11,
                "expected ')' to close the '(' at column 5",
            ),
            ("x = u $ 2; y = 0", 7, "unexpected character '$'"),
            ("x = q; y = 0", 5, "unknown variable 'q'"),
            ("x = 1; x = 2; y = 0", 8, "'x' is assigned twice"),
            ("x = 1", 6, "missing 'y = ...'"),
            ("x = 1; y = 2; 3", 15, "unexpected extra expression"),
            ("u = 1; x = 0; y = 0", 1, "'u' is an input"),
            ("pi = 3; x = 0; y = 0", 1, "'pi' is a constant"),
            ("x = atan2(u); y = 0", 5, "atan2 takes 2 arguments, got 1"),
            ("x = 2 u; y = 0", 7, "missing operator"),
            (
                "x = r; r = 1; y = 0",
                5,
                "'r' is used before it is assigned",
            ),
            ("x = sin; y = 0", 5, "'sin' is a function"),
            ("x = 1..2; y = 0", 5, "malformed number"),
            (
                "x = min(1); y = 0",
                5,
                "min takes 2 or more arguments, got 1",
            ),
        ];
        for (src, col, msg) in cases {
            let e = error(src);
            eprintln!("{src:24} → {e}");
            assert_eq!(e.column, col, "{src}: {e}");
            assert!(e.message.contains(msg), "{src}: {e}");
        }
        // Columns count characters, not bytes.
        let e = error("x = 1 − 2 ×; y = 0");
        assert_eq!(e.column, 12, "{e}");
    }

    #[test]
    fn domain_errors_give_non_finite_values_not_panics() {
        let [x, y] = eval2("x = sqrt(-1); y = 1/0", 0.0, 0.0);
        assert!(x.is_nan() && y.is_infinite());
        let [x, _] = eval2("x = log(0) * 0; y = 0", 0.0, 0.0);
        assert!(x.is_nan());
    }

    #[test]
    fn deep_nesting_is_fine() {
        let src = format!("x = {}u{}; y = 0", "(".repeat(200), ")".repeat(200));
        assert_eq!(eval2(&src, 0.5, 0.0)[0], 0.5);
        let e = error(&format!("x = {}u; y = 0", "-(".repeat(100_000)));
        assert!(e.message.contains("nested more than"), "{e}");
    }
}
