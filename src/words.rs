//! Fixed-size word encodings, for values shared through a sequence lock: the real-time
//! thread writes a value as a few `u64` words (relaxed atomic stores, never waiting), readers
//! read the words back.
//!
//! A type says how many words it takes and how it writes and reads them ([`Packed`]); a
//! struct is packed field by field, in the order of the one list of its fields that
//! [`packed_struct!`] turns into both the struct and its encoding, so the two cannot drift
//! apart (a round-trip test per struct holds them).
//!
//! Must never: import another edmd module, allocate, or lose bits of what it packs.

/// A value that travels as `WORDS` words.
pub trait Packed: Sized {
    const WORDS: usize;
    /// Writes the value into `out` (exactly `WORDS` words).
    fn pack(&self, out: &mut [u64]);
    /// Reads a value from `words` (exactly `WORDS` words).
    fn unpack(words: &[u64]) -> Self;
}

impl Packed for u64 {
    const WORDS: usize = 1;
    fn pack(&self, out: &mut [u64]) {
        out[0] = *self;
    }
    fn unpack(words: &[u64]) -> Self {
        words[0]
    }
}

impl Packed for i64 {
    const WORDS: usize = 1;
    fn pack(&self, out: &mut [u64]) {
        out[0] = *self as u64;
    }
    fn unpack(words: &[u64]) -> Self {
        words[0] as i64
    }
}

impl Packed for f64 {
    const WORDS: usize = 1;
    fn pack(&self, out: &mut [u64]) {
        out[0] = self.to_bits();
    }
    fn unpack(words: &[u64]) -> Self {
        f64::from_bits(words[0])
    }
}

impl Packed for bool {
    const WORDS: usize = 1;
    fn pack(&self, out: &mut [u64]) {
        out[0] = u64::from(*self);
    }
    fn unpack(words: &[u64]) -> Self {
        words[0] != 0
    }
}

impl<T: Packed, const N: usize> Packed for [T; N] {
    const WORDS: usize = N * T::WORDS;
    fn pack(&self, out: &mut [u64]) {
        for (item, slot) in self.iter().zip(out.chunks_exact_mut(T::WORDS)) {
            item.pack(slot);
        }
    }
    fn unpack(words: &[u64]) -> Self {
        std::array::from_fn(|i| T::unpack(&words[i * T::WORDS..(i + 1) * T::WORDS]))
    }
}

/// Defines a struct and packs it field by field, in the order written: the one list of the
/// fields. Every field's type must be [`Packed`].
macro_rules! packed_struct {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $(
                $(#[$field_meta:meta])*
                $field_vis:vis $field:ident : $ty:ty,
            )*
        }
    ) => {
        $(#[$meta])*
        $vis struct $name {
            $(
                $(#[$field_meta])*
                $field_vis $field: $ty,
            )*
        }

        impl $crate::words::Packed for $name {
            const WORDS: usize = 0 $(+ <$ty as $crate::words::Packed>::WORDS)*;

            fn pack(&self, out: &mut [u64]) {
                let mut at = 0;
                $(
                    let n = <$ty as $crate::words::Packed>::WORDS;
                    $crate::words::Packed::pack(&self.$field, &mut out[at..at + n]);
                    at += n;
                )*
                debug_assert_eq!(at, out.len());
            }

            fn unpack(words: &[u64]) -> Self {
                let mut at = 0;
                $(
                    let n = <$ty as $crate::words::Packed>::WORDS;
                    let $field = <$ty as $crate::words::Packed>::unpack(&words[at..at + n]);
                    at += n;
                )*
                debug_assert_eq!(at, words.len());
                $name { $($field,)* }
            }
        }
    };
}

pub(crate) use packed_struct;

#[cfg(test)]
mod tests {
    use super::*;

    packed_struct! {
        #[derive(Debug, Clone, Copy, PartialEq)]
        struct Sample {
            a: u64,
            b: i64,
            c: f64,
            d: bool,
            e: [i64; 3],
        }
    }

    #[test]
    fn a_struct_round_trips_through_its_words() {
        let s = Sample {
            a: u64::MAX,
            b: -5,
            c: f64::NAN,
            d: true,
            e: [1, -2, i64::MIN],
        };
        assert_eq!(Sample::WORDS, 7);
        let mut w = [0u64; 7];
        s.pack(&mut w);
        let back = Sample::unpack(&w);
        assert_eq!((back.a, back.b, back.d, back.e), (s.a, s.b, s.d, s.e));
        assert_eq!(back.c.to_bits(), s.c.to_bits());
    }
}
