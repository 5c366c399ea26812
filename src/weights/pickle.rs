//! The pickle machine: the opcodes `torch.save` emits (protocol 2) and the rest of
//! protocols 0–5 a checkpoint's metadata can hold, run over a `data.pkl`'s bytes without
//! Python. Nothing is imported or executed: a class reference is just its name, and a
//! call goes to [`super::torch_rebuild`], which interprets the few constructors torch uses
//! and keeps every other call as a generic object. Hostile input is bounded (nesting,
//! memo, stack) and named by its byte offset.
//!
//! The opcode table (`Unpickler::run`) is one function over 100 lines by design: one arm
//! per opcode, as in CPython's `_pickle.c` `load`.

use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;

use anyhow::{anyhow, bail, Result};

use super::pickle_value::{new_object, Value};
use super::torch_rebuild::{persistent_load, reduce};

/// Unpickles `bytes` (a `data.pkl`): the root value, persistent ids resolved to storage
/// references. For fuzzing and for files that are a bare pickle.
pub fn unpickle(bytes: &[u8]) -> Result<Value> {
    Unpickler::new(bytes).run()
}

/// The pickle virtual machine (protocols 0–5, no extension registry, no out-of-band buffers).
struct Unpickler<'a> {
    b: &'a [u8],
    at: usize,
    stack: Vec<Value>,
    marks: Vec<usize>,
    memo: HashMap<u32, Value>,
    /// Nesting depth of each container built so far, by address: a hostile pickle could nest
    /// deep enough to overflow the stack when the values are dropped or walked.
    depth: HashMap<usize, u32>,
}

/// Containers nested deeper than this are refused (real checkpoints nest a few dozen deep).
const MAX_NESTING: u32 = 1000;

fn address(v: &Value) -> Option<usize> {
    Some(match v {
        Value::Tuple(r) => Rc::as_ptr(r) as *const () as usize,
        Value::List(r) => Rc::as_ptr(r) as *const () as usize,
        Value::Dict(r) => Rc::as_ptr(r) as *const () as usize,
        Value::Object(r) => Rc::as_ptr(r) as *const () as usize,
        _ => return None,
    })
}

impl<'a> Unpickler<'a> {
    fn new(b: &'a [u8]) -> Self {
        Self {
            b,
            at: 0,
            stack: Vec::new(),
            marks: Vec::new(),
            memo: HashMap::new(),
            depth: HashMap::new(),
        }
    }

    fn depth_of(&self, v: &Value) -> u32 {
        address(v)
            .and_then(|a| self.depth.get(&a).copied())
            .unwrap_or(0)
    }

    fn max_depth(&self, items: &[Value]) -> u32 {
        items.iter().map(|v| self.depth_of(v)).max().unwrap_or(0)
    }

    /// Records that the container on top of the stack holds values `inner` deep.
    fn nest_top(&mut self, inner: u32) -> Result<()> {
        let Some(a) = self.stack.last().and_then(address) else {
            return Ok(());
        };
        let d = self.depth.entry(a).or_insert(0);
        *d = (*d).max(inner + 1);
        if *d > MAX_NESTING {
            bail!(
                "pickle nests containers more than {MAX_NESTING} deep (byte {})",
                self.at
            );
        }
        Ok(())
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or_else(|| anyhow!("pickle ends early at byte {} (wanted {n} more)", self.at))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }
    fn u16(&mut self) -> Result<u16> {
        Ok(u16::from_le_bytes(self.take(2)?.try_into()?))
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into()?))
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into()?))
    }
    fn len(&mut self, n: u64) -> Result<usize> {
        let n = usize::try_from(n)?;
        if n > self.b.len() - self.at {
            bail!(
                "pickle declares {n} bytes at byte {}, only {} left",
                self.at,
                self.b.len() - self.at
            );
        }
        Ok(n)
    }
    fn line(&mut self) -> Result<&'a str> {
        let rest = &self.b[self.at..];
        let end = rest
            .iter()
            .position(|&c| c == b'\n')
            .ok_or_else(|| anyhow!("pickle ends inside a text line at byte {}", self.at))?;
        self.at += end + 1;
        std::str::from_utf8(&rest[..end]).map_err(|_| anyhow!("non-UTF-8 text line in pickle"))
    }

    fn pop(&mut self) -> Result<Value> {
        if self.marks.last().is_some_and(|&m| m >= self.stack.len()) {
            bail!("pickle pops past a mark at byte {}", self.at);
        }
        self.stack
            .pop()
            .ok_or_else(|| anyhow!("pickle stack underflow at byte {}", self.at))
    }

    fn pop_mark(&mut self) -> Result<Vec<Value>> {
        let m = self
            .marks
            .pop()
            .ok_or_else(|| anyhow!("pickle has no mark to pop at byte {}", self.at))?;
        if m > self.stack.len() {
            bail!("corrupt pickle mark at byte {}", self.at);
        }
        Ok(self.stack.split_off(m))
    }

    fn top(&self) -> Result<&Value> {
        self.stack
            .last()
            .ok_or_else(|| anyhow!("pickle stack empty at byte {}", self.at))
    }

    fn memo_get(&self, i: u32) -> Result<Value> {
        self.memo
            .get(&i)
            .cloned()
            .ok_or_else(|| anyhow!("pickle refers to memo entry {i} that was never stored"))
    }

    fn run(mut self) -> Result<Value> {
        loop {
            let pos = self.at;
            let op = self.u8()?;
            match op {
                0x80 => {
                    let p = self.u8()?;
                    if p > 5 {
                        bail!("pickle protocol {p} is not supported (0–5)");
                    }
                }
                0x95 => {
                    self.u64()?; // FRAME: a length hint only
                }
                b'.' => return self.pop(),
                b'(' => self.marks.push(self.stack.len()),
                b'0' => {
                    self.pop()?;
                }
                b'1' => {
                    self.pop_mark()?;
                }
                b'2' => {
                    let v = self.top()?.clone();
                    self.stack.push(v);
                }
                b'N' => self.stack.push(Value::None),
                0x88 => self.stack.push(Value::Bool(true)),
                0x89 => self.stack.push(Value::Bool(false)),
                b'I' => {
                    let l = self.line()?;
                    let v = match l {
                        "00" => Value::Bool(false),
                        "01" => Value::Bool(true),
                        _ => Value::Int(l.trim().parse().map_err(|_| anyhow!("bad INT {l:?}"))?),
                    };
                    self.stack.push(v);
                }
                b'J' => {
                    let v = i32::from_le_bytes(self.take(4)?.try_into()?);
                    self.stack.push(Value::Int(v as i64));
                }
                b'K' => {
                    let v = self.u8()?;
                    self.stack.push(Value::Int(v as i64));
                }
                b'M' => {
                    let v = self.u16()?;
                    self.stack.push(Value::Int(v as i64));
                }
                b'L' => {
                    let l = self.line()?.trim_end_matches('L');
                    let v = l
                        .parse::<i64>()
                        .map(Value::Int)
                        .unwrap_or_else(|_| Value::BigInt(l.as_bytes().into()));
                    self.stack.push(v);
                }
                0x8a | 0x8b => {
                    let n = if op == 0x8a {
                        self.u8()? as u64
                    } else {
                        self.u32()? as u64
                    };
                    let n = self.len(n)?;
                    let b = self.take(n)?;
                    let v = if n <= 8 {
                        let fill = if b.last().is_some_and(|&x| x & 0x80 != 0) {
                            0xff
                        } else {
                            0
                        };
                        let mut full = [fill; 8];
                        full[..n].copy_from_slice(b);
                        Value::Int(i64::from_le_bytes(full))
                    } else {
                        Value::BigInt(b.into())
                    };
                    self.stack.push(v);
                }
                b'F' => {
                    let l = self.line()?;
                    self.stack.push(Value::Float(
                        l.trim().parse().map_err(|_| anyhow!("bad FLOAT {l:?}"))?,
                    ));
                }
                b'G' => {
                    let v = f64::from_be_bytes(self.take(8)?.try_into()?);
                    self.stack.push(Value::Float(v));
                }
                b'S' => {
                    let l = self.line()?;
                    let s = l.trim().trim_matches(|c| c == '\'' || c == '"');
                    self.stack.push(Value::Str(s.into()));
                }
                b'T' | b'U' | b'X' | 0x8c | 0x8d | b'B' | b'C' | 0x8e | 0x96 => {
                    let n = match op {
                        b'U' | 0x8c | b'C' => self.u8()? as u64,
                        b'T' | b'X' | b'B' => self.u32()? as u64,
                        _ => self.u64()?,
                    };
                    let n = self.len(n)?;
                    let b = self.take(n)?;
                    let v = match op {
                        b'B' | b'C' | 0x8e | 0x96 => Value::Bytes(b.into()),
                        _ => Value::Str(String::from_utf8_lossy(b).into()),
                    };
                    self.stack.push(v);
                }
                b'V' => {
                    let l = self.line()?;
                    self.stack.push(Value::Str(l.into()));
                }
                b')' => self.stack.push(Value::Tuple(Rc::new(Vec::new()))),
                b't' => {
                    let items = self.pop_mark()?;
                    let d = self.max_depth(&items);
                    self.stack.push(Value::Tuple(Rc::new(items)));
                    self.nest_top(d)?;
                }
                0x85..=0x87 => {
                    let n = (op - 0x84) as usize;
                    if self.stack.len() < n {
                        bail!("pickle stack underflow at byte {pos}");
                    }
                    let items = self.stack.split_off(self.stack.len() - n);
                    let d = self.max_depth(&items);
                    self.stack.push(Value::Tuple(Rc::new(items)));
                    self.nest_top(d)?;
                }
                b']' => self.stack.push(Value::List(Rc::default())),
                b'l' => {
                    let items = self.pop_mark()?;
                    let d = self.max_depth(&items);
                    self.stack.push(Value::List(Rc::new(RefCell::new(items))));
                    self.nest_top(d)?;
                }
                b'a' => {
                    let v = self.pop()?;
                    self.extend_list(vec![v])?;
                }
                b'e' => {
                    let items = self.pop_mark()?;
                    self.extend_list(items)?;
                }
                b'}' => self.stack.push(Value::Dict(Rc::default())),
                b'd' => {
                    let items = self.pop_mark()?;
                    let d = Value::Dict(Rc::default());
                    self.stack.push(d);
                    self.set_items(items)?;
                }
                b's' => {
                    let v = self.pop()?;
                    let k = self.pop()?;
                    self.set_items(vec![k, v])?;
                }
                b'u' => {
                    let items = self.pop_mark()?;
                    self.set_items(items)?;
                }
                0x8f => self.stack.push(Value::List(Rc::default())),
                0x90 => {
                    let items = self.pop_mark()?;
                    self.extend_list(items)?;
                }
                0x91 => {
                    let items = self.pop_mark()?;
                    let d = self.max_depth(&items);
                    self.stack.push(Value::List(Rc::new(RefCell::new(items))));
                    self.nest_top(d)?;
                }
                b'c' => {
                    let module = self.line()?.to_string();
                    let name = self.line()?.to_string();
                    self.stack.push(Value::Class(Rc::new((module, name))));
                }
                0x93 => {
                    let name = self.pop()?;
                    let module = self.pop()?;
                    match (module.as_str(), name.as_str()) {
                        (Some(m), Some(n)) => self
                            .stack
                            .push(Value::Class(Rc::new((m.to_string(), n.to_string())))),
                        _ => bail!("STACK_GLOBAL needs two strings at byte {pos}"),
                    }
                }
                b'R' => {
                    let args = self.pop()?;
                    let callable = self.pop()?;
                    let d = self.depth_of(&args);
                    let v = reduce(callable, args)?;
                    self.stack.push(v);
                    self.nest_top(d)?;
                }
                // NEWOBJ, and NEWOBJ_EX whose keyword arguments on top are dropped.
                0x81 | 0x92 => {
                    if op == 0x92 {
                        self.pop()?;
                    }
                    let args = self.pop()?;
                    let cls = self.pop()?;
                    let d = self.depth_of(&args);
                    self.stack
                        .push(new_object(&cls, args.elements().unwrap_or_default()));
                    self.nest_top(d)?;
                }
                b'i' => {
                    let module = self.line()?.to_string();
                    let name = self.line()?.to_string();
                    let args = self.pop_mark()?;
                    let cls = Value::Class(Rc::new((module, name)));
                    self.stack.push(new_object(&cls, args));
                }
                b'o' => {
                    let mut items = self.pop_mark()?;
                    if items.is_empty() {
                        bail!("OBJ without a class at byte {pos}");
                    }
                    let cls = items.remove(0);
                    self.stack.push(new_object(&cls, items));
                }
                b'b' => {
                    let state = self.pop()?;
                    let obj = self.top()?.clone();
                    let d = self.depth_of(&state);
                    build(&obj, state)?;
                    self.nest_top(d)?;
                }
                b'p' => {
                    let i: u32 = self.line()?.trim().parse()?;
                    let v = self.top()?.clone();
                    self.memo.insert(i, v);
                }
                b'q' => {
                    let i = self.u8()? as u32;
                    let v = self.top()?.clone();
                    self.memo.insert(i, v);
                }
                b'r' => {
                    let i = self.u32()?;
                    let v = self.top()?.clone();
                    self.memo.insert(i, v);
                }
                0x94 => {
                    let i = self.memo.len() as u32;
                    let v = self.top()?.clone();
                    self.memo.insert(i, v);
                }
                b'g' => {
                    let i: u32 = self.line()?.trim().parse()?;
                    let v = self.memo_get(i)?;
                    self.stack.push(v);
                }
                b'h' => {
                    let i = self.u8()? as u32;
                    let v = self.memo_get(i)?;
                    self.stack.push(v);
                }
                b'j' => {
                    let i = self.u32()?;
                    let v = self.memo_get(i)?;
                    self.stack.push(v);
                }
                b'Q' => {
                    let pid = self.pop()?;
                    self.stack.push(persistent_load(pid)?);
                }
                b'P' => {
                    bail!("text persistent ids (PERSID) are not used by torch.save; byte {pos}")
                }
                other => bail!("unsupported pickle opcode 0x{other:02x} at byte {pos}"),
            }
        }
    }

    fn extend_list(&mut self, items: Vec<Value>) -> Result<()> {
        let d = self.max_depth(&items);
        self.nest_top(d)?;
        match self.top()? {
            Value::List(l) => l.borrow_mut().extend(items),
            Value::Object(o) => o.borrow_mut().elements.extend(items),
            other => bail!("APPEND to a {} at byte {}", other.type_name(), self.at),
        }
        Ok(())
    }

    fn set_items(&mut self, items: Vec<Value>) -> Result<()> {
        if items.len() % 2 != 0 {
            bail!("SETITEMS with an odd number of values at byte {}", self.at);
        }
        let d = self.max_depth(&items);
        self.nest_top(d)?;
        let mut pairs = Vec::with_capacity(items.len() / 2);
        let mut it = items.into_iter();
        while let (Some(k), Some(v)) = (it.next(), it.next()) {
            pairs.push((k, v));
        }
        match self.top()? {
            Value::Dict(d) => d.borrow_mut().extend(pairs),
            Value::Object(o) => o.borrow_mut().items.extend(pairs),
            other => bail!("SETITEM on a {} at byte {}", other.type_name(), self.at),
        }
        Ok(())
    }
}

/// `BUILD`: a dict state updates a dict; anything else becomes an object's state.
fn build(obj: &Value, state: Value) -> Result<()> {
    match obj {
        Value::Object(o) => {
            let mut o = o.borrow_mut();
            // `(dict_state, slots_state)` tuples: keep the dict part.
            let state = match &state {
                Value::Tuple(t) if t.len() == 2 && matches!(t[0], Value::Dict(_) | Value::None) => {
                    t[0].clone()
                }
                _ => state,
            };
            o.state = Some(state);
        }
        Value::Dict(d) => {
            if let Value::Dict(s) = &state {
                let add = s.borrow().clone();
                d.borrow_mut().extend(add);
            }
        }
        // Tensors and other values rebuilt by reduce ignore their state (hooks, metadata).
        _ => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::io::Read;
    use std::path::Path;

    use super::*;

    fn run(b: &[u8]) -> Result<Value> {
        Unpickler::new(b).run()
    }

    #[test]
    fn reads_basic_protocol2_values() {
        // pickle.dumps({'a': [1, -2, 3.5], 'b': (True, None)}, protocol=2)
        let b = b"\x80\x02}q\x00(X\x01\x00\x00\x00aq\x01]q\x02(K\x01J\xfe\xff\xff\xffG@\x0c\x00\x00\x00\x00\x00\x00eX\x01\x00\x00\x00bq\x03\x88N\x86q\x04u.";
        let v = run(b).unwrap();
        let a = v.get("a").unwrap().elements().unwrap();
        assert!(matches!(a[0], Value::Int(1)) && matches!(a[1], Value::Int(-2)));
        assert!(matches!(a[2], Value::Float(x) if x == 3.5));
        let t = v.get("b").unwrap().elements().unwrap();
        assert!(matches!(t[0], Value::Bool(true)) && matches!(t[1], Value::None));
    }

    #[test]
    fn memo_shares_built_objects() {
        // An object built after it was memoized is seen built through the memo (as in Python).
        // c__main__\nA\n)\x81q\x00}X\x01\x00\x00\x00xK\x05sb h\x00 .  → the same object twice in a tuple
        let mut b =
            b"\x80\x02c__main__\nA\nq\x00)\x81q\x01}q\x02X\x01\x00\x00\x00xK\x05sbh\x01\x86."
                .to_vec();
        // (obj, obj) after BUILD
        let v = run(&b).unwrap();
        let t = v.elements().unwrap();
        let Value::Object(o) = &t[1] else { panic!() };
        assert_eq!(o.borrow().class, "__main__.A");
        assert!(matches!(
            o.borrow().state.as_ref().unwrap().get("x"),
            Some(Value::Int(5))
        ));
        b.truncate(5);
        assert!(run(&b).unwrap_err().to_string().contains("ends"));
    }

    #[test]
    fn refuses_deep_nesting_and_survives_damage() {
        // 5000 nested 1-tuples: refused with a message, not a stack overflow.
        let mut b = b"\x80\x02N".to_vec();
        b.extend(std::iter::repeat_n(0x85u8, 5000));
        b.push(b'.');
        let e = run(&b).unwrap_err().to_string();
        assert!(e.contains("more than 1000 deep"), "{e}");
        // Every prefix and every single-byte change of a real torch pickle: an error or a
        // value, never a panic.
        let f = std::fs::File::open(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests/fixtures/ultralytics/reader/stripped.pt"),
        )
        .unwrap();
        let mut ar = zip::ZipArchive::new(f).unwrap();
        let mut pkl = Vec::new();
        ar.by_name("stripped/data.pkl")
            .unwrap()
            .read_to_end(&mut pkl)
            .unwrap();
        let root = run(&pkl).unwrap();
        assert!(root.get("model").unwrap().is_module());
        for n in 0..pkl.len() {
            let _ = run(&pkl[..n]);
            for x in [0x00u8, 0xff, b'(', b't', b'h'] {
                let mut c = pkl.clone();
                c[n] = x;
                let _ = run(&c);
            }
        }
    }

    #[test]
    fn rejects_unknown_opcode_and_underflow() {
        let e = run(b"\x80\x02\xff.").unwrap_err().to_string();
        assert!(
            e.contains("unsupported pickle opcode 0xff at byte 2"),
            "{e}"
        );
        let e = run(b"\x80\x02t.").unwrap_err().to_string();
        assert!(e.contains("mark"), "{e}");
        let e = run(b"\x80\x02h\x07.").unwrap_err().to_string();
        assert!(e.contains("memo entry 7"), "{e}");
    }
}
