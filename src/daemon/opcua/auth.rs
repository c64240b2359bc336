//! Who may do what over OPC UA: everyone may browse, read and subscribe; only a user of
//! `daemon.opcua_users_file`, signed in on the encrypted endpoint, may call Hold and Abort.
//!
//! A name and password are only taken on an endpoint that signs and encrypts: offered on the
//! plain one they would cross the shop network readable. The methods stay visible to
//! anonymous clients (so a client can show them greyed out: `UserExecutable` is false), and a
//! call is refused by the server with `BadUserAccessDenied` before it reaches the daemon.

use std::sync::Arc;

use async_trait::async_trait;
use opcua::crypto::SecurityPolicy;
use opcua::server::ServerEndpoint;
use opcua::server::authenticator::{
    AuthManager, Password, UserToken, user_pass_security_policy_id,
};
use opcua::types::{Error, NodeId, StatusCode, UAString, UserTokenPolicy, UserTokenType};
use parking_lot::RwLock;

use super::users::Users;

/// The policy id of anonymous sign-in (the server's own name for it).
const ANONYMOUS_POLICY: &str = "anonymous";

/// Checks sign-ins against the users in force and keeps the guarded methods from anonymous
/// sessions.
pub struct Gatekeeper {
    users: RwLock<Arc<Users>>,
    /// The methods only a signed-in user may call (set once the address space is built).
    guarded: std::sync::OnceLock<Vec<NodeId>>,
}

impl Gatekeeper {
    pub fn new(users: Users) -> Gatekeeper {
        Gatekeeper {
            users: RwLock::new(Arc::new(users)),
            guarded: std::sync::OnceLock::new(),
        }
    }

    /// Keeps `methods` from anonymous sessions (once; before the server serves).
    pub fn guard(&self, methods: Vec<NodeId>) {
        let _ = self.guarded.set(methods);
    }

    /// Puts `users` in force for the next sign-in (sessions already open keep theirs).
    pub fn set_users(&self, users: Users) {
        *self.users.write() = Arc::new(users);
    }
}

fn encrypted(endpoint: &ServerEndpoint) -> bool {
    endpoint.security_policy() != SecurityPolicy::None
}

#[async_trait]
impl AuthManager for Gatekeeper {
    async fn authenticate_anonymous_token(&self, _endpoint: &ServerEndpoint) -> Result<(), Error> {
        Ok(())
    }

    async fn authenticate_username_identity_token(
        &self,
        endpoint: &ServerEndpoint,
        username: &str,
        password: &Password,
    ) -> Result<UserToken, Error> {
        if !encrypted(endpoint) {
            return Err(Error::new(
                StatusCode::BadIdentityTokenRejected,
                "names and passwords are only taken on the encrypted endpoint",
            ));
        }
        let users = self.users.read().clone();
        if users.check(username, password.get()) {
            tracing::info!("opcua: {username} signed in");
            Ok(UserToken(username.to_string()))
        } else {
            static REFUSED_SIGN_INS: crate::daemon::noise::Budget =
                crate::daemon::noise::Budget::new();
            REFUSED_SIGN_INS.log(format_args!(
                "opcua: sign-in as {username:?} refused: no such user or wrong password"
            ));
            Err(Error::new(
                StatusCode::BadUserAccessDenied,
                "no such user or wrong password",
            ))
        }
    }

    fn is_user_executable(&self, token: &UserToken, method_id: &NodeId) -> bool {
        // Until the methods are known, nothing is callable anonymously.
        let guarded = self.guarded.get().is_none_or(|m| m.contains(method_id));
        !(token.is_anonymous() && guarded)
    }

    fn user_token_policies(&self, endpoint: &ServerEndpoint) -> Vec<UserTokenPolicy> {
        let mut policies = vec![UserTokenPolicy {
            policy_id: UAString::from(ANONYMOUS_POLICY),
            token_type: UserTokenType::Anonymous,
            issued_token_type: UAString::null(),
            issuer_endpoint_url: UAString::null(),
            security_policy_uri: UAString::null(),
        }];
        if encrypted(endpoint) {
            policies.push(UserTokenPolicy {
                policy_id: user_pass_security_policy_id(endpoint),
                token_type: UserTokenType::UserName,
                issued_token_type: UAString::null(),
                issuer_endpoint_url: UAString::null(),
                security_policy_uri: UAString::null(),
            });
        }
        policies
    }
}
