//! A small pickle reader (protocols 2–5): enough of Python's unpickler to read what
//! `torch.save` writes — dicts, lists, tuples, numbers, strings, globals, `REDUCE`/`BUILD`
//! calls and persistent ids — as plain [`Value`]s. Nothing is executed: a global is a
//! name, a call is a record of the callable and its arguments, and the PyTorch reader
//! ([`super::pytorch`]) gives meaning to the few it knows (`_rebuild_tensor_v2`,
//! `OrderedDict`, ...).
//!
//! Limits: values are copied, not shared, so a container changed after it was memoised is
//! seen as it was at `BINPUT` through later `BINGET`s (a state dict never does this).

use anyhow::{bail, Context, Result};

/// A pickled value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    Tuple(Vec<Value>),
    List(Vec<Value>),
    /// Entries in insertion order.
    Dict(Vec<(Value, Value)>),
    /// `module.name`
    Global(String, String),
    /// `callable(*args)` (`REDUCE`, `NEWOBJ`).
    Call(Box<Value>, Box<Value>),
    /// `obj.__setstate__(state)` (`BUILD`).
    Build(Box<Value>, Box<Value>),
    /// A persistent id (`BINPERSID`): PyTorch's storage references.
    PersId(Box<Value>),
}

impl Value {
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }
    pub fn as_int(&self) -> Option<i64> {
        match self {
            Value::Int(i) => Some(*i),
            Value::Bool(b) => Some(*b as i64),
            _ => None,
        }
    }
    /// The items of a tuple or list.
    pub fn as_seq(&self) -> Option<&[Value]> {
        match self {
            Value::Tuple(v) | Value::List(v) => Some(v),
            _ => None,
        }
    }
    /// `Global("collections", "OrderedDict")` → `"collections.OrderedDict"`.
    pub fn global_name(&self) -> Option<String> {
        match self {
            Value::Global(m, n) => Some(format!("{m}.{n}")),
            _ => None,
        }
    }
}

enum Item {
    Mark,
    V(Value),
}

struct Input<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Input<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len());
        let Some(end) = end else {
            bail!("pickle truncated at byte {} (wanted {n} more)", self.at)
        };
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
    fn line(&mut self) -> Result<String> {
        let rest = &self.b[self.at..];
        let n = rest
            .iter()
            .position(|&c| c == b'\n')
            .context("pickle truncated inside a text line")?;
        let s = String::from_utf8_lossy(&rest[..n]).into_owned();
        self.at += n + 1;
        Ok(s)
    }
    fn utf8(&mut self, n: usize) -> Result<String> {
        let at = self.at;
        String::from_utf8(self.take(n)?.to_vec())
            .with_context(|| format!("pickle: invalid UTF-8 string at byte {at}"))
    }
}

/// Little-endian two's-complement integer of `LONG1`/`LONG4`.
fn long(bytes: &[u8]) -> Result<i64> {
    if bytes.is_empty() {
        return Ok(0);
    }
    if bytes.len() > 8 {
        bail!(
            "pickle: integer of {} bytes does not fit in 64 bits",
            bytes.len()
        );
    }
    let neg = bytes[bytes.len() - 1] & 0x80 != 0;
    let mut b = [if neg { 0xff } else { 0 }; 8];
    b[..bytes.len()].copy_from_slice(bytes);
    Ok(i64::from_le_bytes(b))
}

/// Unpickles `bytes` (one pickle, up to `STOP`).
pub fn load(bytes: &[u8]) -> Result<Value> {
    let mut r = Input { b: bytes, at: 0 };
    let mut stack: Vec<Item> = Vec::new();
    let mut memo: std::collections::HashMap<u32, Value> = std::collections::HashMap::new();
    fn pop(stack: &mut Vec<Item>, at: usize) -> Result<Value> {
        match stack.pop() {
            Some(Item::V(v)) => Ok(v),
            Some(Item::Mark) => bail!("pickle: unexpected MARK at byte {at}"),
            None => bail!("pickle: stack underflow at byte {at}"),
        }
    }
    fn pop_mark(stack: &mut Vec<Item>, at: usize) -> Result<Vec<Value>> {
        let mut out = Vec::new();
        loop {
            match stack.pop() {
                Some(Item::V(v)) => out.push(v),
                Some(Item::Mark) => break,
                None => bail!("pickle: no MARK before byte {at}"),
            }
        }
        out.reverse();
        Ok(out)
    }
    fn top(stack: &mut [Item], at: usize) -> Result<&mut Value> {
        match stack.last_mut() {
            Some(Item::V(v)) => Ok(v),
            _ => bail!("pickle: no value on the stack at byte {at}"),
        }
    }
    fn set_items(d: &mut Value, kv: Vec<Value>, at: usize) -> Result<()> {
        if kv.len() % 2 != 0 {
            bail!("pickle: odd number of dict items at byte {at}");
        }
        // SETITEMS on an `OrderedDict()` call: keep the items as the call's state.
        let target = match d {
            Value::Dict(e) => e,
            Value::Call(_, _) => {
                let call = std::mem::replace(d, Value::None);
                *d = Value::Build(Box::new(call), Box::new(Value::Dict(Vec::new())));
                return set_items(d, kv, at);
            }
            Value::Build(_, state) => match state.as_mut() {
                Value::Dict(e) => e,
                _ => bail!("pickle: SETITEMS on a non-dict at byte {at}"),
            },
            _ => bail!("pickle: SETITEMS on a non-dict at byte {at}"),
        };
        let mut it = kv.into_iter();
        while let (Some(k), Some(v)) = (it.next(), it.next()) {
            target.push((k, v));
        }
        Ok(())
    }
    loop {
        let at = r.at;
        let op = r.u8().context("pickle ends before STOP")?;
        match op {
            0x80 => {
                r.u8()?;
            }
            0x95 => {
                r.u64()?;
            }
            b'.' => return pop(&mut stack, at),
            b'(' => stack.push(Item::Mark),
            b'}' => stack.push(Item::V(Value::Dict(Vec::new()))),
            b']' => stack.push(Item::V(Value::List(Vec::new()))),
            b')' => stack.push(Item::V(Value::Tuple(Vec::new()))),
            0x8f => stack.push(Item::V(Value::List(Vec::new()))),
            b'N' => stack.push(Item::V(Value::None)),
            0x88 => stack.push(Item::V(Value::Bool(true))),
            0x89 => stack.push(Item::V(Value::Bool(false))),
            b'J' => {
                let v = r.u32()? as i32;
                stack.push(Item::V(Value::Int(v as i64)))
            }
            b'K' => {
                let v = r.u8()?;
                stack.push(Item::V(Value::Int(v as i64)))
            }
            b'M' => {
                let v = r.u16()?;
                stack.push(Item::V(Value::Int(v as i64)))
            }
            0x8a => {
                let n = r.u8()? as usize;
                let v = long(r.take(n)?)?;
                stack.push(Item::V(Value::Int(v)))
            }
            0x8b => {
                let n = r.u32()? as usize;
                let v = long(r.take(n)?)?;
                stack.push(Item::V(Value::Int(v)))
            }
            b'G' => {
                let v = f64::from_be_bytes(r.take(8)?.try_into()?);
                stack.push(Item::V(Value::Float(v)))
            }
            b'X' => {
                let n = r.u32()? as usize;
                let s = r.utf8(n)?;
                stack.push(Item::V(Value::Str(s)))
            }
            0x8c => {
                let n = r.u8()? as usize;
                let s = r.utf8(n)?;
                stack.push(Item::V(Value::Str(s)))
            }
            0x8d => {
                let n = r.u64()? as usize;
                let s = r.utf8(n)?;
                stack.push(Item::V(Value::Str(s)))
            }
            b'U' => {
                let n = r.u8()? as usize;
                let s = String::from_utf8_lossy(r.take(n)?).into_owned();
                stack.push(Item::V(Value::Str(s)))
            }
            b'T' => {
                let n = r.u32()? as usize;
                let s = String::from_utf8_lossy(r.take(n)?).into_owned();
                stack.push(Item::V(Value::Str(s)))
            }
            b'C' => {
                let n = r.u8()? as usize;
                stack.push(Item::V(Value::Bytes(r.take(n)?.to_vec())))
            }
            b'B' => {
                let n = r.u32()? as usize;
                stack.push(Item::V(Value::Bytes(r.take(n)?.to_vec())))
            }
            0x8e => {
                let n = r.u64()? as usize;
                stack.push(Item::V(Value::Bytes(r.take(n)?.to_vec())))
            }
            b'c' => {
                let m = r.line()?;
                let n = r.line()?;
                stack.push(Item::V(Value::Global(m, n)))
            }
            0x93 => {
                let n = pop(&mut stack, at)?;
                let m = pop(&mut stack, at)?;
                match (m, n) {
                    (Value::Str(m), Value::Str(n)) => stack.push(Item::V(Value::Global(m, n))),
                    _ => bail!("pickle: STACK_GLOBAL needs two strings at byte {at}"),
                }
            }
            b'Q' => {
                let pid = pop(&mut stack, at)?;
                stack.push(Item::V(Value::PersId(Box::new(pid))))
            }
            b'P' => {
                let s = r.line()?;
                stack.push(Item::V(Value::PersId(Box::new(Value::Str(s)))))
            }
            b't' => {
                let v = pop_mark(&mut stack, at)?;
                stack.push(Item::V(Value::Tuple(v)))
            }
            0x85..=0x87 => {
                let n = (op - 0x84) as usize;
                let mut v = Vec::with_capacity(n);
                for _ in 0..n {
                    v.push(pop(&mut stack, at)?);
                }
                v.reverse();
                stack.push(Item::V(Value::Tuple(v)))
            }
            b'l' => {
                let v = pop_mark(&mut stack, at)?;
                stack.push(Item::V(Value::List(v)))
            }
            b'd' => {
                let v = pop_mark(&mut stack, at)?;
                let mut d = Value::Dict(Vec::new());
                set_items(&mut d, v, at)?;
                stack.push(Item::V(d))
            }
            0x91 => {
                let v = pop_mark(&mut stack, at)?;
                stack.push(Item::V(Value::List(v)))
            }
            b'R' | 0x81 => {
                let args = pop(&mut stack, at)?;
                let f = pop(&mut stack, at)?;
                stack.push(Item::V(Value::Call(Box::new(f), Box::new(args))))
            }
            0x92 => {
                let _kwargs = pop(&mut stack, at)?;
                let args = pop(&mut stack, at)?;
                let f = pop(&mut stack, at)?;
                stack.push(Item::V(Value::Call(Box::new(f), Box::new(args))))
            }
            b'b' => {
                let state = pop(&mut stack, at)?;
                let obj = pop(&mut stack, at)?;
                stack.push(Item::V(Value::Build(Box::new(obj), Box::new(state))))
            }
            b's' => {
                let v = pop(&mut stack, at)?;
                let k = pop(&mut stack, at)?;
                set_items(top(&mut stack, at)?, vec![k, v], at)?;
            }
            b'u' => {
                let kv = pop_mark(&mut stack, at)?;
                set_items(top(&mut stack, at)?, kv, at)?;
            }
            b'a' => {
                let v = pop(&mut stack, at)?;
                match top(&mut stack, at)? {
                    Value::List(l) => l.push(v),
                    _ => bail!("pickle: APPEND to a non-list at byte {at}"),
                }
            }
            b'e' | 0x90 => {
                let vs = pop_mark(&mut stack, at)?;
                match top(&mut stack, at)? {
                    Value::List(l) => l.extend(vs),
                    _ => bail!("pickle: APPENDS to a non-list at byte {at}"),
                }
            }
            b'q' => {
                let k = r.u8()? as u32;
                let v = top(&mut stack, at)?.clone();
                memo.insert(k, v);
            }
            b'r' => {
                let k = r.u32()?;
                let v = top(&mut stack, at)?.clone();
                memo.insert(k, v);
            }
            0x94 => {
                let k = memo.len() as u32;
                let v = top(&mut stack, at)?.clone();
                memo.insert(k, v);
            }
            b'h' | b'j' => {
                let k = if op == b'h' { r.u8()? as u32 } else { r.u32()? };
                let v = memo
                    .get(&k)
                    .with_context(|| format!("pickle: memo key {k} unset at byte {at}"))?
                    .clone();
                stack.push(Item::V(v))
            }
            b'0' => {
                stack.pop();
            }
            b'1' => {
                pop_mark(&mut stack, at)?;
            }
            b'2' => {
                let v = top(&mut stack, at)?.clone();
                stack.push(Item::V(v))
            }
            op => bail!("pickle: unsupported opcode 0x{op:02x} at byte {at}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_a_protocol_2_dict_and_names_truncation() {
        // pickle.dumps({'a': (1, -2, 300, 2**40), 'b': [1.5, None, True]}, protocol=2)
        let p = b"\x80\x02}q\x00(X\x01\x00\x00\x00aq\x01(K\x01J\xfe\xff\xff\xffM,\x01\x8a\x06\x00\x00\x00\x00\x00\x01tq\x02X\x01\x00\x00\x00bq\x03]q\x04(G?\xf8\x00\x00\x00\x00\x00\x00N\x88eu.";
        let v = load(p).unwrap();
        assert_eq!(
            v,
            Value::Dict(vec![
                (
                    Value::Str("a".into()),
                    Value::Tuple(vec![
                        Value::Int(1),
                        Value::Int(-2),
                        Value::Int(300),
                        Value::Int(1 << 40)
                    ])
                ),
                (
                    Value::Str("b".into()),
                    Value::List(vec![Value::Float(1.5), Value::None, Value::Bool(true)])
                ),
            ])
        );
        let e = format!("{:#}", load(&p[..20]).unwrap_err());
        assert!(e.contains("truncated") || e.contains("before STOP"), "{e}");
        let e = format!("{:#}", load(b"\x80\x02\xff").unwrap_err());
        assert!(e.contains("unsupported opcode 0xff"), "{e}");
    }
}
