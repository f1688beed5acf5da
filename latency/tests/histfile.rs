//! The histogram file: ours parses back to what was written, and cyclictest's own file (rt-tests
//! 2.40, `cyclictest -m -S -p 80 -i 1000 -D 3 -q -h 20 --histfile=...`) parses too.

use latency::histfile::{Column, parse, write};

fn column(seed: u64, bins: usize) -> Column {
    let counts: Vec<u64> = (0..bins as u64).map(|i| (i * 7919 + seed) % 13).collect();
    let total = counts.iter().sum();
    Column {
        bins: counts,
        total,
        min_us: seed,
        avg_us: seed + 3,
        max_us: 40_000 + seed,
        overflows: 5 + seed,
        overflow_cycles: vec![17, 4711, 99_999],
        others: 2 + seed,
    }
}

#[test]
fn our_file_parses_back_to_the_same_columns() {
    let cols = vec![column(0, 50), column(1, 50), column(2, 50)];
    let text = write(&cols, &["a comment".into(), "columns: a, b, c".into()]);
    assert!(text.starts_with("# a comment\n# columns: a, b, c\n# Histogram\n000000 "));
    assert!(text.contains("\n000049 "));
    assert!(text.contains("# Thread 2: 00017 04711 99999 # 00004 others\n"));
    assert_eq!(parse(&text), Ok(cols));
}

#[test]
fn one_column_without_overflows_round_trips() {
    let mut c = column(3, 10);
    c.overflows = 0;
    c.overflow_cycles.clear();
    c.others = 0;
    let text = write(std::slice::from_ref(&c), &[]);
    assert!(text.contains("# Thread 0:\n"));
    assert_eq!(parse(&text), Ok(vec![c]));
}

#[test]
fn cyclictest_s_own_file_parses() {
    let text = include_str!("data/cyclictest-2.40-h20.hist");
    let cols = parse(text).expect("cyclictest's file");
    assert_eq!(cols.len(), 2);
    for c in &cols {
        assert_eq!(c.bins.len(), 20);
        assert_eq!(c.bins.iter().sum::<u64>(), c.total);
        assert_eq!(c.overflow_cycles.len() as u64 + c.others, c.overflows);
    }
    assert_eq!(cols[0].total, 58);
    assert_eq!((cols[0].min_us, cols[0].max_us), (14, 9875));
    assert_eq!(cols[1].overflows, 2842);
}

#[test]
fn a_damaged_file_is_refused_with_its_line() {
    let good = write(&[column(0, 5)], &[]);
    let bad = good.replace("000002 ", "000003 ");
    assert!(
        parse(&bad)
            .expect_err("bin out of order")
            .contains("line 4")
    );
    let cut: String = good.lines().take(4).map(|l| format!("{l}\n")).collect();
    assert!(parse(&cut).is_err());
    assert!(parse("nothing here\n").is_err());
}
