//! The API's OpenAPI 3 document, served at `/v1/openapi.json`. The paths
//! come from the handlers' `#[utoipa::path]` attributes and the schemas
//! from the body types themselves ([`super::bodies`], the status types of
//! [`crate::serve::state`], [`crate::serve::jobs`] and
//! [`crate::serve::records_index`], the supervisor's
//! [`crate::bench::Readings`]); routes are registered with their
//! description ([`super::router`]), so the document cannot list a route
//! that is not served nor leave one out.

use std::sync::Arc;

use axum::{Extension, Json};
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityRequirement, SecurityScheme};
use utoipa::openapi::OpenApi as Document;
use utoipa::{Modify, OpenApi};

/// Who may call the API: nobody needs a token on loopback or the Unix
/// socket unless the daemon was given one; then every request carries
/// `Authorization: Bearer <token>`.
struct BearerToken;

impl Modify for BearerToken {
    fn modify(&self, api: &mut Document) {
        let components = api.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
        api.security = Some(vec![
            SecurityRequirement::default(),
            SecurityRequirement::new("bearer", Vec::<String>::new()),
        ]);
    }
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "motorbench daemon",
        description = "The control API of `motorbench serve`: rigs, tests (one at a time per rig, \
                       under the safety supervisor), emergency stop, records. See docs/daemon.md."
    ),
    modifiers(&BearerToken),
    tags(
        (name = "daemon", description = "health, this document, metrics"),
        (name = "rigs", description = "rig state, emergency stop, reset"),
        (name = "tests", description = "starting, following and aborting tests"),
        (name = "records", description = "the records index and the records' files"),
    )
)]
struct Base;

/// The document's parts that do not come from a route.
pub fn base() -> Document {
    Base::openapi()
}

/// Complete a document assembled from the routes: every operation may
/// answer `401` (a daemon with a token, a request without it).
pub fn finish(doc: &mut Document) {
    use utoipa::openapi::{ContentBuilder, Ref, RefOr, ResponseBuilder};
    let unauthorized = ResponseBuilder::new()
        .description("the daemon has a token and the request does not carry it")
        .content(
            "application/json",
            ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("ErrorBody")))
                .build(),
        )
        .build();
    for item in doc.paths.paths.values_mut() {
        let operations = [
            &mut item.get,
            &mut item.put,
            &mut item.post,
            &mut item.delete,
            &mut item.options,
            &mut item.head,
            &mut item.patch,
            &mut item.trace,
        ];
        for op in operations.into_iter().flatten() {
            op.responses
                .responses
                .insert("401".into(), RefOr::T(unauthorized.clone()));
        }
    }
}

/// This document.
#[utoipa::path(get, path = "/v1/openapi.json", tag = "daemon",
    responses((status = 200, description = "the OpenAPI 3 document of this API", body = Object)))]
pub async fn document(Extension(doc): Extension<Arc<Document>>) -> Json<Document> {
    Json(doc.as_ref().clone())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_readings_schema_lists_the_readings_fields() {
        let sent = serde_json::to_value(crate::bench::Readings::default()).unwrap();
        let mut sent: Vec<&String> = sent.as_object().unwrap().keys().collect();
        sent.sort();
        let doc = serde_json::to_value(crate::serve::api::openapi_document()).unwrap();
        let schema = &doc["components"]["schemas"]["Readings"]["properties"];
        let mut described: Vec<&String> = schema.as_object().expect("Readings").keys().collect();
        described.sort();
        assert_eq!(sent, described);
    }

    #[test]
    fn a_tests_status_describes_its_operating_points() {
        let doc = serde_json::to_value(crate::serve::api::openapi_document()).unwrap();
        let schemas = &doc["components"]["schemas"];
        let points = &schemas["TestStatus"]["properties"]["operating_points"];
        assert_eq!(points["type"], "array", "{points}");
        assert_eq!(points["items"]["$ref"], "#/components/schemas/PointStatus");
        let fields = schemas["PointStatus"]["properties"].as_object().unwrap();
        for f in [
            "segment",
            "slip",
            "line_current",
            "input_power",
            "winding_temperature",
        ] {
            assert!(fields.contains_key(f), "{f}: {fields:?}");
        }
        // The thermometer's reading is there only where the rig has one.
        let required = schemas["PointStatus"]["required"].as_array().unwrap();
        assert!(
            !required.iter().any(|r| r == "winding_temperature"),
            "{required:?}"
        );
        assert!(required.iter().any(|r| r == "slip"), "{required:?}");
    }

    #[test]
    fn every_route_is_described_once_with_its_answers() {
        let doc = serde_json::to_value(crate::serve::api::openapi_document()).unwrap();
        let paths = doc["paths"].as_object().unwrap();
        assert!(paths.contains_key("/v1/rigs/{rig}/tests"), "{paths:?}");
        assert!(paths.contains_key("/v1/records/{name}/svg"));
        assert!(paths.contains_key("/metrics"));
        for (path, item) in paths {
            for (method, op) in item.as_object().unwrap() {
                let responses = op["responses"].as_object().unwrap();
                assert!(!responses.is_empty(), "{method} {path}");
            }
        }
        assert_eq!(doc["openapi"].as_str().map(|v| &v[..2]), Some("3."));
    }
}
