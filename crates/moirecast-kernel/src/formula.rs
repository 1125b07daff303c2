//! What a user formula z = h(x, y) may hold before it is parsed.
//!
//! exmex parses and differentiates recursively, and its second derivatives
//! grow far faster than the formula: a product of n factors differentiates
//! into n² products, a tower of powers exponentially (41 `x`s joined by `^`
//! took 40 s to parse and 7 ms per surface point). Past a few hundred
//! characters its recursion overflows a 2 MB thread stack (the studio's
//! workers), past a thousand the 8 MB main thread's, and the process
//! aborts. So a formula is measured first, by the rules below, each with a
//! name and a fix; what passes is parsed on a thread of its own with a
//! stack the budget cannot exhaust; and the derivatives it yields are
//! measured again, since every surface point evaluates them.

/// A formula refused by a named rule, or one exmex cannot read.
#[derive(Clone, Debug, PartialEq)]
pub struct FormulaError {
    /// `formula-length`, `formula-depth`, `formula-operations`,
    /// `formula-powers`, `formula-derivatives` or `formula-syntax`.
    pub rule: &'static str,
    pub problem: String,
    pub fix: String,
}

impl std::fmt::Display for FormulaError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} ({})", self.problem, self.rule)
    }
}

/// Most characters.
pub const MAX_CHARS: usize = 200;
/// Deepest nesting of parentheses.
pub const MAX_DEPTH: usize = 8;
/// Most operations: binary operators and function calls.
pub const MAX_OPERATIONS: usize = 24;
/// Most powers (`^`): each differentiates into a logarithm and a product.
pub const MAX_POWERS: usize = 4;
/// Most characters of the five derivatives exmex writes out: each is
/// evaluated at every point of the surface, and at this size a point
/// costs about 20 µs (the shipped kinds: under 1 µs).
pub const MAX_DERIVATIVE_CHARS: usize = 6000;
/// The parsing thread's stack (reserved, not touched): the budget's worst
/// formulas recurse through a few MB.
pub const PARSE_STACK_BYTES: usize = 256 << 20;

fn refuse(rule: &'static str, problem: String, fix: &str) -> FormulaError {
    FormulaError {
        rule,
        problem,
        fix: fix.to_string(),
    }
}

/// Checks `source` against the budget before any parsing: its length, its
/// nesting, its operations and its powers.
pub fn check_budget(source: &str) -> Result<(), FormulaError> {
    let chars = source.chars().count();
    if chars > MAX_CHARS {
        return Err(refuse(
            "formula-length",
            format!("is {chars} characters long, more than {MAX_CHARS}"),
            "write a shorter formula (a surface a device can follow is a few terms)",
        ));
    }
    let (mut depth, mut deepest, mut operations, mut powers) = (0usize, 0usize, 0usize, 0usize);
    let mut previous: Option<char> = None;
    for c in source.chars() {
        match c {
            '(' => {
                depth += 1;
                deepest = deepest.max(depth);
                // a call: a name right before the parenthesis
                if previous.is_some_and(|p| p.is_ascii_alphanumeric() || p == '_') {
                    operations += 1;
                }
            }
            ')' => depth = depth.saturating_sub(1),
            '+' | '-' | '*' | '/' => operations += 1,
            '^' => {
                operations += 1;
                powers += 1;
            }
            _ => {}
        }
        if !c.is_whitespace() {
            previous = Some(c);
        }
    }
    if deepest > MAX_DEPTH {
        return Err(refuse(
            "formula-depth",
            format!("nests parentheses {deepest} deep, more than {MAX_DEPTH}"),
            "expand the nesting (a surface a device can follow is a few terms)",
        ));
    }
    if operations > MAX_OPERATIONS {
        return Err(refuse(
            "formula-operations",
            format!("has {operations} operations (operators and function calls), more than {MAX_OPERATIONS}: its second derivatives grow as their square"),
            "write fewer terms, or a kind of surface that fits (saddle, paraboloid, cylinder, sphere), or sample it into a heightmap",
        ));
    }
    if powers > MAX_POWERS {
        return Err(refuse(
            "formula-powers",
            format!("has {powers} powers (^), more than {MAX_POWERS}"),
            "write x*x for x^2, or use fewer powers",
        ));
    }
    Ok(())
}

/// Checks the derivatives exmex made (their written-out lengths).
pub fn check_derivatives(written: usize) -> Result<(), FormulaError> {
    if written > MAX_DERIVATIVE_CHARS {
        return Err(refuse(
            "formula-derivatives",
            format!("differentiates into {written} characters, more than {MAX_DERIVATIVE_CHARS}: every point of the surface would evaluate them"),
            "write fewer products and powers of x and y",
        ));
    }
    Ok(())
}

/// Runs `parse` on a thread with [`PARSE_STACK_BYTES`] of stack, so the
/// caller's stack (2 MB on a tokio worker) never bounds the recursion.
pub fn on_parse_thread<T: Send + 'static>(
    parse: impl FnOnce() -> T + Send + 'static,
) -> Result<T, FormulaError> {
    std::thread::Builder::new()
        .name("formula".into())
        .stack_size(PARSE_STACK_BYTES)
        .spawn(parse)
        .map_err(|e| {
            refuse(
                "formula-syntax",
                format!("could not be parsed: {e}"),
                "try again",
            )
        })?
        .join()
        .map_err(|_| {
            refuse(
                "formula-syntax",
                "could not be parsed (the parser failed)".into(),
                "write the formula differently",
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_budget_names_each_rule() {
        let rule = |s: &str| check_budget(s).err().map(|e| e.rule);
        assert_eq!(rule("(x*x - y*y)/120 + 0.3*sin(x/7)*cos(y/5)"), None);
        assert_eq!(rule(&"x+".repeat(120)), Some("formula-length"));
        assert_eq!(
            rule(&format!("{}x{}", "(".repeat(9), ")".repeat(9))),
            Some("formula-depth")
        );
        let terms: Vec<String> = (0..18).map(|i| format!("x*y/{}", 1000 + i)).collect();
        assert_eq!(rule(&terms.join("+")), Some("formula-operations"));
        assert_eq!(rule("x^x^x^x^x^x"), Some("formula-powers"));
        assert_eq!(
            rule("sin(sin(sin(sin(sin(sin(sin(sin(sin(x)))))))))"),
            Some("formula-depth")
        );
    }

    /// The formulas that aborted the studio and the command line, parsed
    /// from a thread with a 256 KB stack, and random token soups of every
    /// length: each parses or is refused by a named rule, none aborts.
    #[test]
    fn no_formula_overflows_a_stack() {
        use crate::surface::FormulaSurface;
        let sum = |n: usize| {
            (0..n)
                .map(|i| format!("x*y/{}", 1000 + i))
                .collect::<Vec<_>>()
                .join("+")
        };
        let nested = |d: usize| (0..d).fold("x".to_string(), |f, _| format!("sin({f})"));
        let product =
            |factor: &dyn Fn(usize) -> String| (0..10).map(factor).collect::<Vec<_>>().join("*");
        let mut cases = vec![
            sum(18),
            sum(200),
            nested(9),
            product(&|i| format!("(x+{i})")),
        ];
        cases.push(product(&|_| "(x+y)".to_string()));
        cases.push(
            (0..20)
                .map(|i| format!("sin(x/{})", i + 1))
                .collect::<Vec<_>>()
                .join("+"),
        );
        let tokens = [
            "x", "y", "2", "0.5", "+", "-", "*", "/", "^", "(", ")", "sin(", "exp(", "sqrt(",
        ];
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..200 {
            let mut f = String::new();
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let len = (state % 90) as usize;
            for _ in 0..len {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                f.push_str(tokens[(state % tokens.len() as u64) as usize]);
            }
            cases.push(f);
        }
        let outcomes = std::thread::Builder::new()
            .stack_size(256 << 10)
            .spawn(move || {
                cases
                    .iter()
                    .map(|f| FormulaSurface::parse(f).map(|_| ()).map_err(|e| e.rule))
                    .collect::<Vec<_>>()
            })
            .unwrap()
            .join()
            .expect("no formula aborts");
        assert_eq!(outcomes[0], Err("formula-operations"));
        assert_eq!(outcomes[1], Err("formula-length"));
        assert_eq!(outcomes[2], Err("formula-depth"));
        assert_eq!(outcomes[3], Ok(()), "ten factors of x alone stay small");
        assert_eq!(outcomes[4], Err("formula-derivatives"));
        assert_eq!(outcomes[5], Err("formula-operations"));
        assert!(outcomes.iter().any(|o| o.is_ok()) && outcomes.contains(&Err("formula-syntax")));
    }
}
