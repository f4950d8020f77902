//! Invite codes: the one secret of a session, in a form a person can read aloud, type and
//! check, with every single typo reported at its group.
//!
//! # Format
//!
//! A code is 7 groups of 5 characters joined by dashes: 35 characters, 41 with the dashes.
//!
//! ```text
//! layout:  rrrrc-rrrrc-rrrrc-rrrrc-rrrrc-rrrrc-rrwwc
//! example: m9s38-46q39-d25v7-t4f5d-v37ed-3s3ep-28k6f
//! ```
//!
//! - The alphabet is Crockford's base32 in lowercase, [`ALPHABET`]
//!   (`0123456789abcdefghjkmnpqrstvwxyz`): the digits and the letters without `i`, `l`, `o`
//!   (too like `1`, `1`, `0`) and `u`.
//!   Every character is 5 bits, a symbol of the field GF(32) = GF(2)\[x\] / (x^5 + x^2 + 1),
//!   whose generator is written α below.
//! - `r`: 26 random characters, each drawn uniformly, so a code carries exactly
//!   [`RANDOM_BITS`] = 130 random bits.
//! - `w`: 2 whole-code check characters.
//!   With the 26 random characters they form 28 data characters `d_0..d_27` that satisfy
//!   Σ d_j·α^j = 0 and Σ d_j·α^(2j) = 0: a Reed-Solomon code of distance 3.
//!   A code whose session binds its authors to their admissions
//!   ([`Invite::binds_authors`], made by [`Invite::for_founder`]) satisfies Σ d_j·α^j = 1
//!   instead: no single wrong character turns one kind into the other (it would move the
//!   second sum too), and codes made before read as sessions that do not bind.
//! - `c`: one check character per group, last in the group.
//!   The 5 characters `c_0..c_4` of group `g` (0-based) satisfy Σ c_i·α^i = α^g.
//!
//! # What the checks guarantee
//!
//! - Any one wrong character is detected and reported with its group (the weights α^i of
//!   a group are distinct and nonzero, so a change `e` at `i` moves the sum by `e·α^i ≠ 0`).
//! - Any two characters of one group swapped (adjacent or not) are detected and reported
//!   with their group, since the sum moves by `(α^i + α^k)·(c_i + c_k) ≠ 0`.
//!   Two adjacent characters swapped across a dash make one wrong character in each group:
//!   also detected, reported with the first.
//! - A whole group typed in the wrong place fails its check (each group's target α^g
//!   differs).
//! - Any two wrong characters anywhere are detected: two in different groups fail both
//!   group checks, two in one group that happen to pass its check (a 1 in 32 chance) fail the
//!   whole-code check, which catches every error of at most two data characters.
//! - Not guaranteed: three or more wrong characters in one group slip past both checks with a
//!   chance of about 2^-15, and a random text of 35 characters passes with a chance of 2^-45.
//!
//! # Reading a code
//!
//! [`Invite::parse`] ignores case and surrounding whitespace, reads `o` as `0` and `i`, `l`
//! as `1`, and skips dashes (also the Unicode dashes U+2010 to U+2015 that text editors put
//! in) and whitespace anywhere, since the layout is fixed: groups are counted from the
//! characters, never from the separators.
//! Error columns are 1-based and count characters (not bytes) from the code's first
//! non-blank character.
//! A text that is not of this format at all (a word, a phrase, a short code, an old
//! hexadecimal invite) is refused as [`InviteError::Weak`].
//! So is a text of the right length whose groups mostly fail their checks: that many typos
//! are not typos.
//!
//! # Entropy
//!
//! The 26 random characters each take one of 32 values with equal chance, which is 130
//! random bits; the other 9 characters are functions of them and add none.
//! A session's keys, its discovery id and the admission MACs are derived from the code, so a
//! discovery server, a LAN listener or a fake peer that sees a derived value can test
//! guesses offline, as fast as its hardware hashes.
//! At 10^12 guesses a second (a large farm of GPUs) finding one code takes 2^129 / 10^12
//! seconds on average, about 2·10^19 years.
//! A word or a phrase a person makes up has 20 to 50 bits and falls in seconds to days,
//! which is why only codes of this format are accepted.

use std::fmt;
use std::str::FromStr;

use rand_core::CryptoRngCore;

use crate::identity::PeerId;
use crate::membership::{COMMITMENT_SYMBOLS, FOUNDER_NONCE_BYTES, FounderCommitment};

/// Longest text [`Invite::parse`] reads, in bytes, surrounding whitespace included; longer
/// input is refused before any other work.
pub const MAX_INVITE_BYTES: usize = 256;
/// The characters of a code, by value (Crockford's base32 in lowercase).
pub const ALPHABET: &[u8; 32] = b"0123456789abcdefghjkmnpqrstvwxyz";
/// Characters in a group, its check character included.
pub const GROUP_CHARS: usize = 5;
/// Groups in a code.
pub const N_GROUPS: usize = 7;
/// Characters in a code, not counting the dashes.
pub const CODE_CHARS: usize = GROUP_CHARS * N_GROUPS;
/// Characters in a code's canonical text, dashes included.
pub const CODE_TEXT_CHARS: usize = CODE_CHARS + N_GROUPS - 1;
/// Random characters in a code.
pub const RANDOM_CHARS: usize = 26;
/// Random bits in a code (5 per random character).
pub const RANDOM_BITS: u32 = 130;
const _: () = assert!(RANDOM_CHARS == COMMITMENT_SYMBOLS);

/// Data characters in a group (all but its check character).
const GROUP_DATA_CHARS: usize = GROUP_CHARS - 1;
/// Data characters in a code: the random ones and the 2 whole-code check characters.
const DATA_CHARS: usize = GROUP_DATA_CHARS * N_GROUPS;
/// Bits of one character.
const CHAR_BITS: u32 = 5;

const _: () = assert!(RANDOM_BITS == RANDOM_CHARS as u32 * CHAR_BITS);
const _: () = assert!(DATA_CHARS == RANDOM_CHARS + 2);
const _: () = assert!(
    RANDOM_BITS >= 128,
    "an invite must carry at least 128 random bits"
);

/// An invite code: the secret that opens a session (see the [module docs](self) for the
/// format).
///
/// `Display` prints the canonical code (lowercase, dashes between groups); `Debug` prints
/// `Invite(..)`, never the code.
/// Equality compares in variable time: it is for local checks, such as a stored invite
/// against a given one; a remote proves the invite through admission MACs instead.
///
/// ```
/// use rand_chacha::ChaCha20Rng;
/// use rand_core::SeedableRng;
/// use replication::net::invite::Invite;
///
/// // A real invite needs an RNG seeded from the operating system.
/// let invite = Invite::generate(&mut ChaCha20Rng::seed_from_u64(7));
/// let typed = invite.to_string().to_uppercase().replace('-', " ");
/// assert_eq!(Invite::parse(&typed)?, invite);
/// assert!(Invite::parse("password").is_err());
/// # Ok::<(), replication::net::invite::InviteError>(())
/// ```
#[derive(Clone, PartialEq, Eq)]
pub struct Invite {
    /// The code's characters by value (each below 32), check characters included.
    symbols: [u8; CODE_CHARS],
}

impl Invite {
    /// A new invite: [`RANDOM_BITS`] random bits from `rng`, plus its check characters.
    pub fn generate(rng: &mut impl CryptoRngCore) -> Invite {
        let mut random = [0; RANDOM_CHARS];
        rng.fill_bytes(&mut random);
        for r in &mut random {
            // 256 is a multiple of 32, so the low 5 bits of a uniform byte are uniform.
            *r &= SYMBOL_MASK;
        }
        Self::from_random(random, UNBOUND_SYNDROMES)
    }

    /// A new invite for a session founded by `founder`: its random characters are
    /// [`FounderCommitment::of`] the founder's key and `nonce` (a secret from the system's
    /// RNG, kept beside the invite), so the founder can prove itself to every member and
    /// expel members ([`crate::membership`]). It carries as many unpredictable bits as a
    /// drawn one while the nonce stays secret. Its session binds its authors to their
    /// admissions ([`Invite::binds_authors`]).
    pub fn for_founder(founder: &PeerId, nonce: &[u8; FOUNDER_NONCE_BYTES]) -> Invite {
        Self::from_random(FounderCommitment::of(founder, nonce).0, BOUND_SYNDROMES)
    }

    /// An invite of a founded session made before sessions bound their authors (what
    /// [`Invite::for_founder`] made then), for tests of such sessions.
    #[doc(hidden)]
    pub fn for_founder_unbound(founder: &PeerId, nonce: &[u8; FOUNDER_NONCE_BYTES]) -> Invite {
        Self::from_random(FounderCommitment::of(founder, nonce).0, UNBOUND_SYNDROMES)
    }

    /// True if the session binds its authors to their admissions
    /// ([`crate::Log::bind_authors`]): every peer reads it from the code alike.
    pub fn binds_authors(&self) -> bool {
        whole_syndromes(&self.data()) == BOUND_SYNDROMES
    }

    /// What this invite commits to: its random characters. Only an invite made by
    /// [`Invite::for_founder`] has a founder who matches it.
    pub fn founder_commitment(&self) -> FounderCommitment {
        let mut symbols = [0; COMMITMENT_SYMBOLS];
        symbols.copy_from_slice(&self.data()[..RANDOM_CHARS]);
        FounderCommitment(symbols)
    }

    /// The invite whose random characters are `random` (each below 32) and whose whole-code
    /// sums are `syndromes`.
    fn from_random(random: [u8; RANDOM_CHARS], syndromes: [u8; 2]) -> Invite {
        let mut data = [0; DATA_CHARS];
        data[..RANDOM_CHARS].copy_from_slice(&random);
        let [w0, w1] = whole_check_chars(&data, syndromes);
        data[RANDOM_CHARS] = w0;
        data[RANDOM_CHARS + 1] = w1;
        let mut symbols = [0; CODE_CHARS];
        for (group_idx, (group, group_data)) in symbols
            .chunks_exact_mut(GROUP_CHARS)
            .zip(data.chunks_exact(GROUP_DATA_CHARS))
            .enumerate()
        {
            group[..GROUP_DATA_CHARS].copy_from_slice(group_data);
            group[GROUP_DATA_CHARS] = group_check_char(group_idx, group_data);
        }
        let invite = Invite { symbols };
        assert!(
            invite.n_failed_groups() == 0 && whole_syndromes(&invite.data()) == syndromes,
            "a generated invite passes its own checks"
        );
        invite
    }

    /// Reads an invite as a person typed or pasted it (see the [module docs](self) for what
    /// is tolerated).
    pub fn parse(text: &str) -> Result<Invite, InviteError> {
        if text.len() > MAX_INVITE_BYTES {
            return Err(InviteError::TooLong {
                n_bytes: text.len(),
            });
        }
        let scan = Scan::new(text.trim());
        if scan.n_chars() == 0 {
            return Err(InviteError::Empty);
        }
        if !scan.looks_like_an_invite() {
            return Err(InviteError::Weak);
        }
        if let Some((column, character)) = scan.first_strange {
            return Err(InviteError::BadCharacter { column, character });
        }
        let (symbols, columns) = scan.code()?;
        let invite = Invite { symbols };
        let n_failed = invite.n_failed_groups();
        if 2 * n_failed > N_GROUPS {
            // Most groups wrong is no typo: this was never an invite.
            return Err(InviteError::Weak);
        }
        if let Some(group_idx) = (0..N_GROUPS).find(|&g| !invite.group_passes(g)) {
            return Err(InviteError::Typo {
                group: group_idx + 1,
                first_column: columns[group_idx * GROUP_CHARS],
                last_column: columns[group_idx * GROUP_CHARS + GROUP_CHARS - 1],
            });
        }
        if ![UNBOUND_SYNDROMES, BOUND_SYNDROMES].contains(&whole_syndromes(&invite.data())) {
            return Err(InviteError::Checksum);
        }
        Ok(invite)
    }

    /// A key derived from the canonical code with blake3 under `context`; the code itself
    /// never leaves this module except through `Display`.
    pub(crate) fn derive_key(&self, context: &str) -> [u8; 32] {
        blake3::derive_key(context, &self.canonical())
    }

    /// The canonical code as ASCII bytes: lowercase, dashes between groups.
    pub(crate) fn canonical(&self) -> [u8; CODE_TEXT_CHARS] {
        let mut text = [b'-'; CODE_TEXT_CHARS];
        for (char_idx, &symbol) in self.symbols.iter().enumerate() {
            text[char_idx + char_idx / GROUP_CHARS] = ALPHABET[usize::from(symbol)];
        }
        text
    }

    /// The 28 data characters (each group without its check character).
    fn data(&self) -> [u8; DATA_CHARS] {
        let mut data = [0; DATA_CHARS];
        for (d, group) in data
            .chunks_exact_mut(GROUP_DATA_CHARS)
            .zip(self.symbols.chunks_exact(GROUP_CHARS))
        {
            d.copy_from_slice(&group[..GROUP_DATA_CHARS]);
        }
        data
    }

    /// Whether group `group_idx` (0-based) satisfies its check.
    fn group_passes(&self, group_idx: usize) -> bool {
        let start = group_idx * GROUP_CHARS;
        let group = &self.symbols[start..start + GROUP_CHARS];
        weighted_sum(group) == alpha_pow(group_idx)
    }

    /// How many groups fail their check.
    fn n_failed_groups(&self) -> usize {
        (0..N_GROUPS).filter(|&g| !self.group_passes(g)).count()
    }
}

impl fmt::Display for Invite {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for byte in self.canonical() {
            fmt::Write::write_char(f, char::from(byte))?;
        }
        Ok(())
    }
}

impl fmt::Debug for Invite {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // The code is a secret: it must not reach logs through `{:?}`.
        f.write_str("Invite(..)")
    }
}

impl FromStr for Invite {
    type Err = InviteError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Invite::parse(text)
    }
}

/// Why [`Invite::parse`] refused a text.
/// Columns are 1-based and count characters from the first non-blank one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum InviteError {
    /// Nothing but whitespace and dashes.
    #[error("the invite code is empty")]
    Empty,
    /// Over [`MAX_INVITE_BYTES`], surrounding whitespace included.
    #[error(
        "the invite code is {n_bytes} bytes, over the limit of {MAX_INVITE_BYTES}: an invite \
         is {CODE_TEXT_CHARS} characters"
    )]
    TooLong {
        /// The length of the text given.
        n_bytes: usize,
    },
    /// A character that is neither in [`ALPHABET`] (or a look-alike) nor a separator.
    #[error(
        "{character:?} at column {column} cannot be in an invite code, which has only digits \
         and the letters a-z except u (i, l and o read as 1, 1 and 0)"
    )]
    BadCharacter {
        /// Where it is.
        column: usize,
        /// The character.
        character: char,
    },
    /// The dashes or spaces split the code into 7 groups, and this one has not 5 characters.
    #[error(
        "group {group} (columns {first_column}-{last_column}) has {n_chars} characters, not \
         {GROUP_CHARS}: check it for a missing or extra character"
    )]
    GroupLength {
        /// The group, from 1.
        group: usize,
        /// The column of its first character.
        first_column: usize,
        /// The column of its last character.
        last_column: usize,
        /// How many characters it has.
        n_chars: usize,
    },
    /// Not [`CODE_CHARS`] characters, and the separators do not say where one is missing or
    /// extra.
    #[error(
        "the invite code has {n_chars} characters, not {CODE_CHARS} ({N_GROUPS} groups of \
         {GROUP_CHARS}, dashes and spaces not counted): check it for a missing or extra \
         character"
    )]
    WrongLength {
        /// How many characters it has, separators not counted.
        n_chars: usize,
    },
    /// A group fails its check: one of its characters is wrong, or two are swapped.
    #[error(
        "typo in group {group} (columns {first_column}-{last_column}): a character is wrong \
         or two are swapped; compare that group with the original"
    )]
    Typo {
        /// The first group that fails, from 1.
        group: usize,
        /// The column of its first character.
        first_column: usize,
        /// The column of its last character.
        last_column: usize,
    },
    /// Every group passes its check but the whole code does not: several wrong characters.
    #[error(
        "the invite code has several typos that the group checks cannot place (two or more \
         wrong characters in one group); compare it with the original"
    )]
    Checksum,
    /// Not of the invite format at all (a word, a phrase, a short or old code): refused,
    /// since such a code can be guessed.
    #[error(
        "this is not an invite code made by sculpt ({N_GROUPS} groups of {GROUP_CHARS} \
         letters and digits); a code made up by hand can be guessed, so make one with \
         `sculpt invite`"
    )]
    Weak,
}

/// The 5 bits of a character's value.
const SYMBOL_MASK: u8 = 0b1_1111;
/// A value that is not a character's, in [`DECODE`].
const NOT_A_SYMBOL: u8 = u8::MAX;
/// Each ASCII byte's value as a character of a code (case and look-alikes folded), or
/// [`NOT_A_SYMBOL`].
const DECODE: [u8; 128] = decode_table();

const fn decode_table() -> [u8; 128] {
    let mut table = [NOT_A_SYMBOL; 128];
    let mut value = 0;
    while value < ALPHABET.len() {
        let lower = ALPHABET[value];
        table[lower as usize] = value as u8;
        table[lower.to_ascii_uppercase() as usize] = value as u8;
        value += 1;
    }
    let look_alikes = [(b'o', 0), (b'i', 1), (b'l', 1)];
    let mut idx = 0;
    while idx < look_alikes.len() {
        let (letter, value) = look_alikes[idx];
        table[letter as usize] = value;
        table[letter.to_ascii_uppercase() as usize] = value;
        idx += 1;
    }
    table
}

/// The value of `c` as a character of a code, if it is one.
fn symbol_of(c: char) -> Option<u8> {
    let byte = u8::try_from(c).ok()?;
    let value = *DECODE.get(usize::from(byte))?;
    (value != NOT_A_SYMBOL).then_some(value)
}

/// Whether `c` separates groups: dashes (ASCII and the Unicode hyphens and dashes U+2010 to
/// U+2015) and whitespace.
fn is_separator(c: char) -> bool {
    matches!(c, '-' | '\u{2010}'..='\u{2015}') || c.is_whitespace()
}

/// A run of characters between separators in a typed code.
#[derive(Debug, Clone, Copy)]
struct Run {
    first_column: usize,
    last_column: usize,
    n_chars: usize,
}

/// What [`Invite::parse`] reads of a trimmed text before checking it.
struct Scan {
    /// The characters of the alphabet, by value, with their columns.
    symbols: Vec<(u8, usize)>,
    /// How many other characters (not separators) there are.
    n_strange: usize,
    /// The first other character, with its column.
    first_strange: Option<(usize, char)>,
    /// The runs between separators.
    runs: Vec<Run>,
}

impl Scan {
    fn new(text: &str) -> Scan {
        assert!(
            text.len() <= MAX_INVITE_BYTES,
            "the text is bounded before the scan"
        );
        let mut scan = Scan {
            symbols: Vec::new(),
            n_strange: 0,
            first_strange: None,
            runs: Vec::new(),
        };
        let mut in_run = false;
        for (column, c) in (1..).zip(text.chars()) {
            if is_separator(c) {
                in_run = false;
                continue;
            }
            match scan.runs.last_mut() {
                Some(run) if in_run => {
                    run.last_column = column;
                    run.n_chars += 1;
                }
                _ => scan.runs.push(Run {
                    first_column: column,
                    last_column: column,
                    n_chars: 1,
                }),
            }
            in_run = true;
            match symbol_of(c) {
                Some(symbol) => scan.symbols.push((symbol, column)),
                None => {
                    scan.n_strange += 1;
                    scan.first_strange.get_or_insert((column, c));
                }
            }
        }
        scan
    }

    /// Characters other than separators.
    fn n_chars(&self) -> usize {
        self.symbols.len() + self.n_strange
    }

    /// Whether the text is close enough to the format that its errors are typos: within a
    /// group's length of [`CODE_CHARS`] and, unless its length is right, split (if at all)
    /// mostly into groups of [`GROUP_CHARS`]. Anything else is a made-up or old code.
    fn looks_like_an_invite(&self) -> bool {
        let n_chars = self.n_chars();
        if n_chars == CODE_CHARS {
            return true;
        }
        let n_full_runs = self
            .runs
            .iter()
            .filter(|run| run.n_chars == GROUP_CHARS)
            .count();
        n_chars.abs_diff(CODE_CHARS) <= GROUP_CHARS
            && (self.runs.len() < 3 || 2 * n_full_runs >= self.runs.len())
    }

    /// The code's characters and their columns, once there is no strange character.
    fn code(&self) -> Result<([u8; CODE_CHARS], [usize; CODE_CHARS]), InviteError> {
        if self.symbols.len() != CODE_CHARS {
            let uneven_group = (self.runs.len() == N_GROUPS)
                .then(|| {
                    (1..)
                        .zip(&self.runs)
                        .find(|(_, run)| run.n_chars != GROUP_CHARS)
                })
                .flatten();
            return Err(match uneven_group {
                Some((group, run)) => InviteError::GroupLength {
                    group,
                    first_column: run.first_column,
                    last_column: run.last_column,
                    n_chars: run.n_chars,
                },
                None => InviteError::WrongLength {
                    n_chars: self.symbols.len(),
                },
            });
        }
        let mut symbols = [0; CODE_CHARS];
        let mut columns = [0; CODE_CHARS];
        for ((symbol, column), &(s, c)) in symbols.iter_mut().zip(&mut columns).zip(&self.symbols) {
            *symbol = s;
            *column = c;
        }
        Ok((symbols, columns))
    }
}

/// Exponents and logarithms of GF(32) = GF(2)\[x\] / (x^5 + x^2 + 1), generator α = x.
struct Field {
    /// α^e for e in 0..62 (twice over, so sums of two logarithms need no reduction).
    exp: [u8; 2 * FIELD_ORDER],
    /// log_α(v) for v in 1..32 (entry 0 unused).
    log: [u8; 32],
}

/// Nonzero elements of GF(32): the order of α.
const FIELD_ORDER: usize = 31;
/// x^5 + x^2 + 1, primitive over GF(2).
const FIELD_POLY: u8 = 0b10_0101;
const FIELD: Field = field();

const fn field() -> Field {
    let mut field = Field {
        exp: [0; 2 * FIELD_ORDER],
        log: [0; 32],
    };
    let mut value: u8 = 1;
    let mut e = 0;
    while e < FIELD_ORDER {
        field.exp[e] = value;
        field.exp[e + FIELD_ORDER] = value;
        field.log[value as usize] = e as u8;
        value <<= 1;
        if value & 0b10_0000 != 0 {
            value ^= FIELD_POLY;
        }
        e += 1;
    }
    field
}

/// α^e.
fn alpha_pow(e: usize) -> u8 {
    FIELD.exp[e % FIELD_ORDER]
}

/// a·b in GF(32).
fn mul(a: u8, b: u8) -> u8 {
    if a == 0 || b == 0 {
        return 0;
    }
    FIELD.exp[usize::from(FIELD.log[usize::from(a)]) + usize::from(FIELD.log[usize::from(b)])]
}

/// a / b in GF(32); `b` is nonzero.
fn div(a: u8, b: u8) -> u8 {
    assert!(b != 0, "division by zero in GF(32)");
    if a == 0 {
        return 0;
    }
    let log_a = usize::from(FIELD.log[usize::from(a)]);
    FIELD.exp[log_a + FIELD_ORDER - usize::from(FIELD.log[usize::from(b)])]
}

/// Σ c_i·α^i over a group's characters.
fn weighted_sum(chars: &[u8]) -> u8 {
    chars
        .iter()
        .enumerate()
        .fold(0, |sum, (i, &c)| sum ^ mul(c, alpha_pow(i)))
}

/// The check character that makes group `group_idx` (its data characters `data`) sum to
/// α^group_idx.
fn group_check_char(group_idx: usize, data: &[u8]) -> u8 {
    let missing = alpha_pow(group_idx) ^ weighted_sum(data);
    div(missing, alpha_pow(GROUP_DATA_CHARS))
}

/// The whole-code sums of a session that does not bind its authors (every code made before).
const UNBOUND_SYNDROMES: [u8; 2] = [0, 0];
/// The whole-code sums of a session that binds its authors ([`Invite::binds_authors`]).
const BOUND_SYNDROMES: [u8; 2] = [1, 0];

/// The two syndromes Σ d_j·α^j and Σ d_j·α^(2j) of the data characters: [`UNBOUND_SYNDROMES`]
/// or [`BOUND_SYNDROMES`] for a code.
fn whole_syndromes(data: &[u8; DATA_CHARS]) -> [u8; 2] {
    data.iter().enumerate().fold([0, 0], |[s1, s2], (j, &d)| {
        [s1 ^ mul(d, alpha_pow(j)), s2 ^ mul(d, alpha_pow(2 * j))]
    })
}

/// The whole-code check characters `d_26`, `d_27` that give the random characters of `data`
/// (its last two entries are ignored) the whole-code sums `target`.
fn whole_check_chars(data: &[u8; DATA_CHARS], target: [u8; 2]) -> [u8; 2] {
    let mut random = *data;
    random[RANDOM_CHARS] = 0;
    random[RANDOM_CHARS + 1] = 0;
    let [s1, s2] = whole_syndromes(&random);
    let (s1, s2) = (s1 ^ target[0], s2 ^ target[1]);
    // Solve a·p + b·q = s1 and a·r + b·s = s2 for the two check characters a, b (Cramer's
    // rule; the determinant is α^49 + α^48, nonzero, and minus is plus in GF(32)).
    let (p, q) = (alpha_pow(RANDOM_CHARS), alpha_pow(RANDOM_CHARS + 1));
    let (r, s) = (
        alpha_pow(2 * RANDOM_CHARS),
        alpha_pow(2 * (RANDOM_CHARS + 1)),
    );
    let det = mul(p, s) ^ mul(q, r);
    let a = div(mul(s1, s) ^ mul(q, s2), det);
    let b = div(mul(p, s2) ^ mul(r, s1), det);
    [a, b]
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use rand_chacha::ChaCha20Rng;
    use rand_core::{RngCore, SeedableRng};

    use super::*;

    fn invite(seed: u64) -> Invite {
        Invite::generate(&mut ChaCha20Rng::seed_from_u64(seed))
    }

    /// The 1-based columns of group `group_idx` (0-based) in a canonical code.
    fn canonical_columns(group_idx: usize) -> (usize, usize) {
        let first = group_idx * (GROUP_CHARS + 1) + 1;
        (first, first + GROUP_CHARS - 1)
    }

    /// The canonical text of `invite` with the `char_idx`-th code character (dashes not
    /// counted) replaced by `replacement`.
    fn with_char(invite: &Invite, char_idx: usize, replacement: char) -> String {
        invite
            .to_string()
            .chars()
            .enumerate()
            .map(|(idx, c)| {
                if idx == char_idx + char_idx / GROUP_CHARS {
                    replacement
                } else {
                    c
                }
            })
            .collect()
    }

    fn typo_in(group_idx: usize) -> InviteError {
        let (first_column, last_column) = canonical_columns(group_idx);
        InviteError::Typo {
            group: group_idx + 1,
            first_column,
            last_column,
        }
    }

    #[test]
    fn generated_codes_round_trip_and_have_the_documented_layout() {
        for seed in 0..50 {
            let invite = invite(seed);
            let text = invite.to_string();
            assert_eq!(text.len(), CODE_TEXT_CHARS);
            let groups: Vec<&str> = text.split('-').collect();
            assert_eq!(groups.len(), N_GROUPS);
            assert!(groups.iter().all(|g| g.len() == GROUP_CHARS));
            assert!(text.bytes().all(|b| b == b'-' || ALPHABET.contains(&b)));
            assert_eq!(Invite::parse(&text), Ok(invite.clone()));
            assert_eq!(text.parse::<Invite>(), Ok(invite));
        }
    }

    #[test]
    fn a_founders_invite_says_its_session_binds_authors_and_no_typo_changes_that() {
        let founder = crate::identity::Keypair::from_seed([3; 32]).peer_id();
        let bound = Invite::for_founder(&founder, &[5; 32]);
        let old = Invite::for_founder_unbound(&founder, &[5; 32]);
        assert!(bound.binds_authors() && !old.binds_authors());
        assert!(
            !invite(1).binds_authors(),
            "a drawn invite has no founder to bind to"
        );
        assert_ne!(bound, old);
        assert_eq!(bound.founder_commitment(), old.founder_commitment());
        for text in [bound.to_string(), old.to_string()] {
            let parsed = Invite::parse(&text).unwrap();
            assert_eq!(parsed.to_string(), text);
            // Every one wrong character is refused, never read as the other kind of session.
            for (i, c) in text.char_indices().filter(|(_, c)| *c != '-') {
                for &b in ALPHABET.iter().filter(|&&b| char::from(b) != c) {
                    let mut typo = text.clone().into_bytes();
                    typo[i] = b;
                    let typo = String::from_utf8(typo).unwrap();
                    assert!(Invite::parse(&typo).is_err(), "{typo}");
                }
            }
        }
    }

    #[test]
    fn a_founders_invite_parses_and_commits_to_its_founder_alone() {
        let founder = crate::identity::Keypair::from_seed([3; 32]).peer_id();
        let other = crate::identity::Keypair::from_seed([4; 32]).peer_id();
        let invite = Invite::for_founder(&founder, &[5; 32]);
        let parsed = Invite::parse(&invite.to_string()).expect("a founder's invite parses");
        let commitment = parsed.founder_commitment();
        assert!(commitment.is_founder(&founder, &[5; 32]));
        assert!(!commitment.is_founder(&other, &[5; 32]));
        assert!(!commitment.is_founder(&founder, &[6; 32]));
        assert_ne!(Invite::for_founder(&founder, &[6; 32]), invite);
    }

    #[test]
    fn known_codes_still_parse() {
        // Codes computed outside this module (the integration tests' invites): a change of
        // alphabet, weights or field would strand every stored invite, and fails here.
        for code in [
            "7m6ev-tzwff-057jy-6w0z1-mdsgb-ppr41-n5kh6",
            "jjx9f-k1qqv-xv5sj-z7vzr-sgty0-1e832-6vb7f",
            "m9s38-46q39-d25v7-t4f5d-v37ed-3s3ep-28k6f",
        ] {
            assert_eq!(Invite::parse(code).map(|i| i.to_string()), Ok(code.into()));
        }
    }

    #[test]
    fn field_tables_are_a_field() {
        for a in 1..32 {
            assert_eq!(mul(a, div(1, a)), 1);
            for b in 1..32 {
                assert_eq!(div(mul(a, b), b), a);
            }
        }
        let distinct: BTreeSet<u8> = (0..FIELD_ORDER).map(alpha_pow).collect();
        assert_eq!(
            distinct.len(),
            FIELD_ORDER,
            "α generates every nonzero element"
        );
    }

    #[test]
    fn a_thousand_seeded_codes_are_distinct() {
        let codes: BTreeSet<String> = (0..1000).map(|seed| invite(seed).to_string()).collect();
        assert_eq!(codes.len(), 1000);
        let mut rng = ChaCha20Rng::seed_from_u64(1);
        let codes: BTreeSet<String> = (0..1000)
            .map(|_| Invite::generate(&mut rng).to_string())
            .collect();
        assert_eq!(codes.len(), 1000);
    }

    #[test]
    fn every_single_substitution_is_reported_at_its_group() {
        for seed in 0..20 {
            let invite = invite(seed);
            let text = invite.to_string();
            for char_idx in 0..CODE_CHARS {
                let original = text.as_bytes()[char_idx + char_idx / GROUP_CHARS];
                for &replacement in ALPHABET.iter().filter(|&&c| c != original) {
                    let typed = with_char(&invite, char_idx, char::from(replacement));
                    let error = Invite::parse(&typed);
                    assert_eq!(error, Err(typo_in(char_idx / GROUP_CHARS)), "{typed}");
                    let column = char_idx + char_idx / GROUP_CHARS + 1;
                    let (first, last) = canonical_columns(char_idx / GROUP_CHARS);
                    assert!((first..=last).contains(&column));
                }
            }
        }
    }

    #[test]
    fn swaps_within_a_group_and_across_a_dash_are_detected() {
        for seed in 0..50 {
            let invite = invite(seed);
            let plain: Vec<char> = invite.to_string().chars().filter(|&c| c != '-').collect();
            for group_idx in 0..N_GROUPS {
                for i in 0..GROUP_CHARS {
                    for k in i + 1..GROUP_CHARS {
                        let (a, b) = (group_idx * GROUP_CHARS + i, group_idx * GROUP_CHARS + k);
                        if plain[a] == plain[b] {
                            continue;
                        }
                        let mut swapped = plain.clone();
                        swapped.swap(a, b);
                        let typed = dashed(&swapped);
                        assert_eq!(Invite::parse(&typed), Err(typo_in(group_idx)), "{typed}");
                    }
                }
            }
            // Typed without dashes, the last character of a group swapped with the next.
            for group_idx in 0..N_GROUPS - 1 {
                let a = group_idx * GROUP_CHARS + GROUP_CHARS - 1;
                if plain[a] == plain[a + 1] {
                    continue;
                }
                let mut swapped = plain.clone();
                swapped.swap(a, a + 1);
                let typed: String = swapped.iter().collect();
                let first_column = group_idx * GROUP_CHARS + 1;
                assert_eq!(
                    Invite::parse(&typed),
                    Err(InviteError::Typo {
                        group: group_idx + 1,
                        first_column,
                        last_column: first_column + GROUP_CHARS - 1,
                    })
                );
            }
        }
    }

    fn dashed(chars: &[char]) -> String {
        chars
            .chunks(GROUP_CHARS)
            .map(|group| group.iter().collect::<String>())
            .collect::<Vec<_>>()
            .join("-")
    }

    #[test]
    fn any_two_substitutions_are_detected() {
        let mut rng = ChaCha20Rng::seed_from_u64(3);
        let invite = invite(3);
        let plain: Vec<char> = invite.to_string().chars().filter(|&c| c != '-').collect();
        for a in 0..CODE_CHARS {
            for b in a + 1..CODE_CHARS {
                for _ in 0..8 {
                    let mut typed = plain.clone();
                    for idx in [a, b] {
                        let shift = 1 + rng.next_u32() as usize % (ALPHABET.len() - 1);
                        let value = ALPHABET.iter().position(|&c| char::from(c) == typed[idx]);
                        let value = (value.unwrap() + shift) % ALPHABET.len();
                        typed[idx] = char::from(ALPHABET[value]);
                    }
                    let typed = dashed(&typed);
                    assert!(Invite::parse(&typed).is_err(), "{typed}");
                }
            }
        }
    }

    #[test]
    fn two_typos_one_group_check_misses_fail_the_whole_code_check() {
        // Find two substitutions in one group that keep its sum: the group check passes.
        let invite = invite(4);
        let mut symbols = invite.symbols;
        let e = 7;
        symbols[0] ^= e;
        symbols[1] ^= div(mul(e, alpha_pow(0)), alpha_pow(1));
        let typed = Invite { symbols };
        assert_eq!(typed.n_failed_groups(), 0);
        assert_eq!(
            Invite::parse(&typed.to_string()),
            Err(InviteError::Checksum)
        );
    }

    #[test]
    fn spellings_of_one_code_parse_to_the_same_invite() {
        let mut n_look_alikes = 0;
        for seed in 0..50 {
            let invite = invite(seed);
            let text = invite.to_string();
            let look_alike = text.replace('0', "O").replace('1', "l");
            n_look_alikes += usize::from(look_alike != text);
            let spellings = [
                text.to_uppercase(),
                text.replace('-', ""),
                text.replace('-', " "),
                text.replace('-', " - "),
                text.replace('-', "\u{2013}"),
                format!("  \t{text}\r\n"),
                format!("{}{}", &text[..3], &text[3..].replacen('-', "--", 2)),
                look_alike,
                text.replace('0', "o").replace('1', "I"),
            ];
            for spelling in spellings {
                assert_eq!(Invite::parse(&spelling), Ok(invite.clone()), "{spelling}");
            }
        }
        assert!(n_look_alikes > 0, "some code has a 0 or a 1");
    }

    #[test]
    fn made_up_and_old_codes_are_refused_as_weak() {
        for weak in [
            "password",
            "abcd-efgh",
            "hunter2",
            "correct horse battery staple",
            "пароль",
            // The hexadecimal invites of earlier versions.
            "7c1d-0a9e-55b2-e46f-93d8-2b7a-c0f1-6e35",
            "aaaaa-aaaaa-aaaaa-aaaaa-aaaaa-aaaaa-aaaaa",
            "0123456789abcdefghjkmnpqrstvwxyz012",
            &"x".repeat(MAX_INVITE_BYTES),
        ] {
            assert_eq!(Invite::parse(weak), Err(InviteError::Weak), "{weak}");
        }
        assert!(InviteError::Weak.to_string().contains("`sculpt invite`"));
    }

    #[test]
    fn empty_over_long_and_strange_input_is_refused() {
        for empty in ["", "  \n", " - - "] {
            assert_eq!(Invite::parse(empty), Err(InviteError::Empty));
        }
        let text = invite(5).to_string();
        let padded = format!("{text}{}", " ".repeat(MAX_INVITE_BYTES));
        assert_eq!(
            Invite::parse(&padded),
            Err(InviteError::TooLong {
                n_bytes: padded.len()
            })
        );
        for strange in ['é', 'u', '!', '\0', '🦀'] {
            let typed = with_char(&invite(5), 12, strange);
            assert_eq!(
                Invite::parse(&format!(" {typed}")),
                Err(InviteError::BadCharacter {
                    column: 15,
                    character: strange
                }),
                "{typed}"
            );
        }
    }

    #[test]
    fn missing_and_extra_characters_are_counted() {
        let text = invite(6).to_string();
        let short = format!("{}{}", &text[..14], &text[15..]);
        assert_eq!(
            Invite::parse(&short),
            Err(InviteError::GroupLength {
                group: 3,
                first_column: 13,
                last_column: 16,
                n_chars: 4
            })
        );
        let long = format!("{}x{}", &text[..14], &text[14..]);
        assert_eq!(
            Invite::parse(&long),
            Err(InviteError::GroupLength {
                group: 3,
                first_column: 13,
                last_column: 18,
                n_chars: 6
            })
        );
        let plain = text.replace('-', "");
        assert_eq!(
            Invite::parse(&plain[1..]),
            Err(InviteError::WrongLength { n_chars: 34 })
        );
        assert_eq!(
            Invite::parse(&format!("{plain}0")),
            Err(InviteError::WrongLength { n_chars: 36 })
        );
    }

    #[test]
    fn debug_hides_the_code_and_errors_name_positions() {
        let invite = invite(8);
        let debug = format!("{invite:?}");
        assert_eq!(debug, "Invite(..)");
        assert!(!debug.contains(&invite.to_string()[..GROUP_CHARS]));
        let typo = typo_in(2).to_string();
        assert!(typo.contains("group 3 (columns 13-17)"), "{typo}");
        let bad = InviteError::BadCharacter {
            column: 4,
            character: 'u',
        };
        assert!(bad.to_string().contains("column 4"));
    }

    #[test]
    fn keys_are_derived_from_the_canonical_text() {
        let invite = invite(9);
        let upper = Invite::parse(&invite.to_string().to_uppercase().replace('-', " ")).unwrap();
        assert_eq!(invite.derive_key("a"), upper.derive_key("a"));
        assert_ne!(invite.derive_key("a"), invite.derive_key("b"));
        assert_ne!(invite.derive_key("a"), self::invite(10).derive_key("a"));
    }
}
