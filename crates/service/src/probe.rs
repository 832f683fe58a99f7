//! `irs-planner healthcheck`: one GET against a running server, for a container's HEALTHCHECK
//! (the runtime image has no curl). Exit 0 on a 2xx answer within the timeout, 1 otherwise.

use http_body_util::Empty;
use hyper_util::client::legacy::Client;
use hyper_util::rt::TokioExecutor;
use std::time::Duration;

/// The URL a server started with `bind` answers on locally: an unspecified address (0.0.0.0,
/// [::]) is reached on loopback.
pub fn local_url(bind: std::net::SocketAddr, path: &str) -> String {
    let host = match bind.ip() {
        ip if ip.is_unspecified() && ip.is_ipv4() => "127.0.0.1".to_string(),
        ip if ip.is_unspecified() => "[::1]".to_string(),
        std::net::IpAddr::V6(ip) => format!("[{ip}]"),
        std::net::IpAddr::V4(ip) => ip.to_string(),
    };
    format!("http://{host}:{}{path}", bind.port())
}

/// GETs `url`; the status on an answer within `timeout`, else why there was none.
pub fn probe(url: &str, timeout: Duration) -> Result<u16, String> {
    let uri: axum::http::Uri = url.parse().map_err(|e| format!("--url {url:?}: {e}"))?;
    if uri.scheme_str() != Some("http") {
        return Err(format!("--url {url:?}: only http:// is probed"));
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| e.to_string())?;
    runtime.block_on(async {
        let client = Client::builder(TokioExecutor::new()).build_http::<Empty<bytes::Bytes>>();
        match tokio::time::timeout(timeout, client.get(uri)).await {
            Ok(Ok(response)) => Ok(response.status().as_u16()),
            Ok(Err(e)) => Err(format!("GET {url}: {e}")),
            Err(_) => Err(format!("GET {url}: no answer within {timeout:?}")),
        }
    })
}
