//! The library's named values on the command line: the library's enums know their names and a
//! line of help each (`Filter::name`, `Filter::about`, ...) and stay free of clap; this module
//! gives clap a parser for each, whose errors, suggestions and `--help` lists are those a
//! derived `ValueEnum` would give.

use std::ffi::OsStr;
use std::marker::PhantomData;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use vortex_tiler::codec::{Bc7Effort, PngLevel, Subsampling};
use vortex_tiler::pyramid::Filter;
use vortex_tiler::settings::CodecChoice;

/// A library enum that flags take by name.
pub trait Named: Copy + Send + Sync + 'static {
    /// Every value, in the order `--help` lists them.
    const ALL: &'static [Self];
    fn name(self) -> &'static str;
    fn about(self) -> &'static str;
}

/// `Named` from the type's own `ALL`, `name` and `about`.
macro_rules! named {
    ($($t:ty),* $(,)?) => {$(
        impl Named for $t {
            const ALL: &'static [Self] = &<$t>::ALL;
            fn name(self) -> &'static str {
                <$t>::name(self)
            }
            fn about(self) -> &'static str {
                <$t>::about(self)
            }
        }
    )*};
}

named!(CodecChoice, Subsampling, PngLevel, Bc7Effort);

impl Named for Filter {
    // The label filters too, which `Filter::ALL` (the filters of images) leaves out.
    const ALL: &'static [Self] = &Filter::NAMED;
    fn name(self) -> &'static str {
        Filter::name(self)
    }
    fn about(self) -> &'static str {
        Filter::about(self)
    }
}

/// The parser of a flag that takes a `T` by name: `#[arg(value_parser = named::<Filter>())]`.
pub fn named<T: Named>() -> NameParser<T> {
    NameParser(PhantomData)
}

#[derive(Clone)]
pub struct NameParser<T>(PhantomData<T>);

fn possible_values<T: Named>() -> impl Iterator<Item = PossibleValue> {
    T::ALL.iter().map(|v| PossibleValue::new(v.name()).help(v.about()))
}

impl<T: Named> TypedValueParser for NameParser<T> {
    type Value = T;

    fn parse_ref(&self, cmd: &clap::Command, arg: Option<&clap::Arg>, value: &OsStr) -> Result<T, clap::Error> {
        // clap's own check of a name against a list, hence its error, with the list and a
        // suggestion of the nearest name, word for word as a `ValueEnum` has it.
        let name = PossibleValuesParser::new(possible_values::<T>()).parse_ref(cmd, arg, value)?;
        // No flag of ours ignores case: the name is one of ours exactly.
        T::ALL
            .iter()
            .copied()
            .find(|v| v.name() == name)
            .ok_or_else(|| clap::Error::new(clap::error::ErrorKind::InvalidValue).with_cmd(cmd))
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = PossibleValue> + '_>> {
        Some(Box::new(possible_values::<T>()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every name parses to its value, and `info.json`'s parsing (`from_name`) agrees.
    fn round_trip<T: Named + PartialEq + std::fmt::Debug>(from_name: fn(&str) -> Option<T>) {
        let cmd = clap::Command::new("test");
        for &v in T::ALL {
            assert_eq!(named::<T>().parse_ref(&cmd, None, OsStr::new(v.name())).ok(), Some(v));
            assert_eq!(from_name(v.name()), Some(v));
            assert!(!v.about().ends_with('.'), "clap drops a help line's last full stop; {v:?} keeps its");
        }
        assert!(named::<T>().parse_ref(&cmd, None, OsStr::new("no-such-value")).is_err());
    }

    #[test]
    fn every_name_parses_to_its_value() {
        round_trip(CodecChoice::from_name);
        round_trip(Subsampling::from_name);
        round_trip(PngLevel::from_name);
        round_trip(Bc7Effort::from_name);
        round_trip(Filter::from_name);
    }
}
