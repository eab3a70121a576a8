//! Independent evaluations on several cores. Each job builds its own environment and policy and
//! is a function of its inputs alone, so results are the same, in the same order, whatever the
//! number of threads.
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The cores to use by default: all the machine has.
pub fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `f` over `items` on up to `threads` threads, results in the items' order. The first error
/// (in item order) is returned.
pub(crate) fn map_in_order<T: Sync, R: Send, E: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> Result<R, E> + Sync,
) -> Result<Vec<R>, E> {
    let threads = threads.clamp(1, items.len().max(1));
    if threads == 1 {
        return items.iter().map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<Result<R, E>>>> = items.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= items.len() {
                    break;
                }
                let r = f(&items[i]);
                *slots[i].lock().unwrap() = Some(r);
            });
        }
    });
    slots.into_iter().map(|s| s.into_inner().unwrap().expect("every item ran")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_and_errors_do_not_depend_on_threads() {
        let items: Vec<u64> = (0..37).collect();
        let f = |x: &u64| if *x == 20 || *x == 30 { Err(*x) } else { Ok(x * x) };
        for threads in [1, 2, 5] {
            assert_eq!(map_in_order(&items, threads, f), Err(20));
            let ok = map_in_order(&items[..20], threads, f).unwrap();
            assert_eq!(ok, (0..20).map(|x| x * x).collect::<Vec<u64>>());
        }
        assert_eq!(map_in_order(&[] as &[u64], 4, f), Ok(vec![]));
    }
}
