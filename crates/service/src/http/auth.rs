//! Authentication at the door: the middleware that asks identity ([`Tokens::caller`]) who is
//! calling, answers 401 when it refuses, and hands the [`Caller`] to the handlers as an
//! extractor. The rules (which tokens, which methods need one) live in `app::identity`.

use super::problem::ApiError;
use crate::app::App;
use crate::app::identity::{Caller, Tokens};
use axum::extract::{FromRequestParts, Request, State};
use axum::http::{Method, header, request::Parts};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

impl<S: Send + Sync> FromRequestParts<S> for Caller {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, Self::Rejection> {
        Ok(parts
            .extensions
            .get::<Caller>()
            .cloned()
            .unwrap_or(Caller::Open))
    }
}

/// Middleware: resolves the caller from `Authorization` and refuses unauthenticated writes.
pub(crate) async fn authenticate(
    State(state): State<App>,
    mut request: Request,
    next: Next,
) -> Response {
    let tokens: &Tokens = state.tokens();
    let presented = request
        .headers()
        .get(header::AUTHORIZATION)
        .map(|v| v.to_str().unwrap_or(""));
    let writes = matches!(
        *request.method(),
        Method::POST | Method::DELETE | Method::PUT | Method::PATCH
    );
    match tokens.caller(presented, writes) {
        Ok(caller) => {
            request.extensions_mut().insert(caller);
            next.run(request).await
        }
        Err(refused) => ApiError::from(refused).into_response(),
    }
}
