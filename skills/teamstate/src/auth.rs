//! Who may write what: the team's public keys, a robot's signing key, and the signatures that
//! travel with records and messages.
//!
//! Without [`TeamSecurity`] (the simulator's default) every well-formed message is believed, as
//! in one process with a modelled radio. With it, each record carries its writer's Ed25519
//! signature, checked by every robot whoever relayed it, so a relay cannot forge or alter another
//! robot's records; and each message carries its sender's signature over the whole message, so
//! acknowledgements and "you have everything" flags cannot be forged either (a forged
//! acknowledgement would make the real sender stop offering records the peer never got).
//!
//! Signed bytes start with a domain tag and the team's name, so a signature made for one kind of
//! data or one team is worthless for another.

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

use ed25519_dalek::{Signer, SigningKey, VerifyingKey};
use serde::{Deserialize, Serialize};
use spomp_core::RobotId;

/// Length of a signature, bytes.
pub const SIGNATURE_BYTES: usize = 64;
/// Length of a public or secret key, bytes.
pub const KEY_BYTES: usize = 32;

const RECORD_DOMAIN: &[u8] = b"spomp team record v1\0";
const MESSAGE_DOMAIN: &[u8] = b"spomp team message v1\0";

/// An Ed25519 signature.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Signature(pub [u8; SIGNATURE_BYTES]);

impl fmt::Debug for Signature {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Signature({:02x}{:02x}{:02x}{:02x}…)", self.0[0], self.0[1], self.0[2], self.0[3])
    }
}

impl Serialize for Signature {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(&self.0)
    }
}

impl<'de> Deserialize<'de> for Signature {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Bytes;
        impl<'de> serde::de::Visitor<'de> for Bytes {
            type Value = Signature;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{SIGNATURE_BYTES} signature bytes")
            }
            fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<Signature, E> {
                <[u8; SIGNATURE_BYTES]>::try_from(v).map(Signature).map_err(|_| E::invalid_length(v.len(), &self))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Signature, A::Error> {
                let mut out = [0u8; SIGNATURE_BYTES];
                for (i, b) in out.iter_mut().enumerate() {
                    *b = seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                if seq.next_element::<u8>()?.is_some() {
                    return Err(serde::de::Error::invalid_length(SIGNATURE_BYTES + 1, &self));
                }
                Ok(Signature(out))
            }
        }
        d.deserialize_bytes(Bytes)
    }
}

/// Why a key could not be made from bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    /// Not 32 bytes, or not a point of the curve.
    #[error("not an Ed25519 public key")]
    BadPublicKey,
}

/// The public keys of a team: who is a member, and how to check what each one signed.
///
/// Members are the robots and the operators (issue 37): an operator is a member like a robot
/// (it may send sync messages and relay), and only an operator's key may write operator
/// commands ([`crate::OperatorCommand`]).
#[derive(Clone)]
pub struct TeamKeys {
    team: String,
    members: BTreeMap<RobotId, VerifyingKey>,
    /// The members whose key issues operator commands (a subset of `members`).
    operators: std::collections::BTreeSet<RobotId>,
}

impl fmt::Debug for TeamKeys {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TeamKeys")
            .field("team", &self.team)
            .field("members", &self.members.keys())
            .field("operators", &self.operators)
            .finish()
    }
}

impl TeamKeys {
    /// The keys of team `team` (the mission's name: signatures of another team do not check).
    pub fn new(team: impl Into<String>) -> Self {
        TeamKeys { team: team.into(), members: BTreeMap::new(), operators: Default::default() }
    }

    /// Adds an operator with its 32-byte public key: a member whose key (and only whose key)
    /// issues operator commands. The operator's id must not be a robot's.
    pub fn add_operator(&mut self, operator: RobotId, public_key: &[u8; KEY_BYTES]) -> Result<(), KeyError> {
        self.add(operator.clone(), public_key)?;
        self.operators.insert(operator);
        Ok(())
    }

    /// Whether `id` is an operator of the team (its key may issue operator commands).
    pub fn is_operator(&self, id: &RobotId) -> bool {
        self.operators.contains(id)
    }

    /// The operators, in id order.
    pub fn operators(&self) -> impl Iterator<Item = &RobotId> {
        self.operators.iter()
    }

    /// Adds a member with its 32-byte public key.
    pub fn add(&mut self, robot: RobotId, public_key: &[u8; KEY_BYTES]) -> Result<(), KeyError> {
        let key = VerifyingKey::from_bytes(public_key).map_err(|_| KeyError::BadPublicKey)?;
        self.members.insert(robot, key);
        Ok(())
    }

    /// The team's name.
    pub fn team(&self) -> &str {
        &self.team
    }

    /// Whether `robot` is a member (a robot or an operator).
    pub fn is_member(&self, robot: &RobotId) -> bool {
        self.members.contains_key(robot)
    }

    /// The members (robots and operators), in id order.
    pub fn members(&self) -> impl Iterator<Item = &RobotId> {
        self.members.keys()
    }

    /// Whether `signature` is `robot`'s over `data` of `domain`.
    fn verify(&self, domain: &[u8], robot: &RobotId, data: &[u8], signature: &Signature) -> bool {
        let Some(key) = self.members.get(robot) else { return false };
        let sig = ed25519_dalek::Signature::from_bytes(&signature.0);
        key.verify_strict(&signed_bytes(domain, &self.team, data), &sig).is_ok()
    }
}

fn signed_bytes(domain: &[u8], team: &str, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(domain.len() + team.len() + 1 + data.len());
    out.extend_from_slice(domain);
    out.extend_from_slice(team.as_bytes());
    out.push(0);
    out.extend_from_slice(data);
    out
}

/// A robot's secret signing key and the team's public keys: what a robot needs to sign its own
/// records and messages and to check everyone else's.
#[derive(Clone)]
pub struct TeamSecurity {
    robot: RobotId,
    signing: SigningKey,
    keys: Arc<TeamKeys>,
}

impl fmt::Debug for TeamSecurity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TeamSecurity").field("robot", &self.robot).field("keys", &self.keys).finish_non_exhaustive()
    }
}

/// Why a robot's security could not be set up.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SecurityError {
    /// The robot is not in the team's public keys.
    #[error("robot `{0}` is not a member of the team's public keys")]
    NotAMember(RobotId),
    /// The secret key does not belong to the public key the team lists for the robot.
    #[error("the secret key of `{0}` does not match its public key in the team's key file")]
    KeyMismatch(RobotId),
}

impl TeamSecurity {
    /// Robot `robot` with its 32-byte secret key, in a team with `keys`. The secret key must
    /// match the public key the team lists for the robot.
    pub fn new(robot: RobotId, secret_key: &[u8; KEY_BYTES], keys: Arc<TeamKeys>) -> Result<Self, SecurityError> {
        let signing = SigningKey::from_bytes(secret_key);
        match keys.members.get(&robot) {
            None => Err(SecurityError::NotAMember(robot)),
            Some(public) if *public != signing.verifying_key() => Err(SecurityError::KeyMismatch(robot)),
            Some(_) => Ok(TeamSecurity { robot, signing, keys }),
        }
    }

    /// The public key of a 32-byte secret key.
    pub fn public_key_of(secret_key: &[u8; KEY_BYTES]) -> [u8; KEY_BYTES] {
        SigningKey::from_bytes(secret_key).verifying_key().to_bytes()
    }

    /// The robot that signs.
    pub fn robot(&self) -> &RobotId {
        &self.robot
    }

    /// The team's public keys.
    pub fn keys(&self) -> &TeamKeys {
        &self.keys
    }

    pub(crate) fn sign_record(&self, data: &[u8]) -> Signature {
        Signature(self.signing.sign(&signed_bytes(RECORD_DOMAIN, &self.keys.team, data)).to_bytes())
    }

    pub(crate) fn sign_message(&self, data: &[u8]) -> Signature {
        Signature(self.signing.sign(&signed_bytes(MESSAGE_DOMAIN, &self.keys.team, data)).to_bytes())
    }

    pub(crate) fn record_signed_by(&self, writer: &RobotId, data: &[u8], signature: &Signature) -> bool {
        self.keys.verify(RECORD_DOMAIN, writer, data, signature)
    }

    pub(crate) fn message_signed_by(&self, sender: &RobotId, data: &[u8], signature: &Signature) -> bool {
        self.keys.verify(MESSAGE_DOMAIN, sender, data, signature)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn team(names: &[(&str, u8)]) -> Arc<TeamKeys> {
        let mut keys = TeamKeys::new("t");
        for (name, seed) in names {
            keys.add(RobotId::new(name), &TeamSecurity::public_key_of(&[*seed; 32])).unwrap();
        }
        Arc::new(keys)
    }

    #[test]
    fn a_signature_checks_only_for_its_signer_domain_and_data() {
        let keys = team(&[("a", 1), ("b", 2)]);
        let a = TeamSecurity::new(RobotId::new("a"), &[1; 32], keys.clone()).unwrap();
        let b = TeamSecurity::new(RobotId::new("b"), &[2; 32], keys.clone()).unwrap();
        let sig = a.sign_record(b"claim");
        assert!(b.record_signed_by(&RobotId::new("a"), b"claim", &sig));
        assert!(!b.record_signed_by(&RobotId::new("b"), b"claim", &sig), "another signer");
        assert!(!b.record_signed_by(&RobotId::new("a"), b"claim!", &sig), "other data");
        assert!(!b.message_signed_by(&RobotId::new("a"), b"claim", &sig), "other domain");
        assert!(!b.record_signed_by(&RobotId::new("x"), b"claim", &sig), "non-member");
        let other_team = Arc::new(TeamKeys { team: "u".into(), ..(*keys).clone() });
        assert!(!keys.is_operator(&RobotId::new("a")));
        let a2 = TeamSecurity::new(RobotId::new("a"), &[1; 32], other_team).unwrap();
        assert!(!b.record_signed_by(&RobotId::new("a"), b"claim", &a2.sign_record(b"claim")), "other team");
    }

    #[test]
    fn a_secret_key_must_match_the_team_file() {
        let keys = team(&[("a", 1)]);
        assert_eq!(
            TeamSecurity::new(RobotId::new("a"), &[9; 32], keys.clone()).unwrap_err(),
            SecurityError::KeyMismatch(RobotId::new("a"))
        );
        assert_eq!(
            TeamSecurity::new(RobotId::new("z"), &[1; 32], keys).unwrap_err(),
            SecurityError::NotAMember(RobotId::new("z"))
        );
    }

    #[test]
    fn signatures_round_trip_through_postcard_and_json() {
        let sig = Signature([7; 64]);
        let bytes = postcard::to_stdvec(&sig).unwrap();
        assert_eq!(postcard::from_bytes::<Signature>(&bytes).unwrap(), sig);
        let json = serde_json::to_string(&sig).unwrap();
        assert_eq!(serde_json::from_str::<Signature>(&json).unwrap(), sig);
        assert!(postcard::from_bytes::<Signature>(&postcard::to_stdvec(&[1u8; 63].as_slice()).unwrap()).is_err());
    }
}
