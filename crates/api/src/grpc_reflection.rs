//! gRPC server reflection, `grpc.reflection.v1` and `grpc.reflection.v1alpha`, answered from the
//! API's own descriptors.
//!
//! tonic-reflection's service ends the whole stream with a status when one request fails (an
//! unknown symbol or file ends it with `NOT_FOUND`), so a client that asks about a name it
//! guessed loses the stream and every answer after it. The protocol answers such a request
//! inside the stream, with an `ErrorResponse` (its code and message), and goes on reading:
//! this service does, as grpc-go's and grpc-java's do. It also sends a file's dependencies with
//! it (as those do), so a client needs one round trip per symbol.
//!
//! Reflection is open, like `grpc.health.v1.Health`: it describes the API's services and
//! messages (what the proto file in the repository says), never a tenant's data, and grpcurl
//! resolves every call through it, a health check included.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use prost::Message;
use prost_types::{DescriptorProto, EnumDescriptorProto, FileDescriptorProto, FileDescriptorSet};

/// The descriptors reflection serves, indexed by file name and by fully qualified symbol.
#[derive(Debug, Default)]
pub struct Descriptors {
    /// Each file, decoded (for its dependencies) and encoded (as answers carry it).
    files: HashMap<String, (FileDescriptorProto, Vec<u8>)>,
    /// Fully qualified symbol (service, method, message, enum, enum value, field) to file name.
    symbols: HashMap<String, String>,
    services: Vec<String>,
}

/// What one reflection request is answered with, whatever the protocol version.
#[derive(Debug, Clone, PartialEq)]
pub enum Answer {
    /// Encoded `FileDescriptorProto`s: the file asked about first, then its dependencies.
    Files(Vec<Vec<u8>>),
    Services(Vec<String>),
    /// No extensions are declared: an empty list for the type.
    ExtensionNumbers(String),
    /// An in-stream error: the request failed, the stream goes on.
    Error(tonic::Code, String),
}

/// A reflection request, whatever the protocol version.
#[derive(Debug, Clone)]
pub enum Asked {
    FileByFilename(String),
    FileContainingSymbol(String),
    FileContainingExtension(String, i32),
    AllExtensionNumbersOfType(String),
    ListServices,
    Nothing,
}

impl Descriptors {
    /// Indexes encoded `FileDescriptorSet`s; a file named twice is kept once.
    pub fn new(sets: &[&[u8]]) -> Result<Self, prost::DecodeError> {
        let mut descriptors = Self::default();
        for set in sets {
            for file in FileDescriptorSet::decode(*set)?.file {
                let name = file.name().to_string();
                if descriptors.files.contains_key(&name) {
                    continue;
                }
                descriptors.index_file(&file);
                let encoded = file.encode_to_vec();
                descriptors.files.insert(name, (file, encoded));
            }
        }
        descriptors.services.sort();
        Ok(descriptors)
    }

    fn index_file(&mut self, file: &FileDescriptorProto) {
        let name = file.name().to_string();
        let package = file.package();
        for message in &file.message_type {
            self.index_message(&name, package, message);
        }
        for enumeration in &file.enum_type {
            self.index_enum(&name, package, enumeration);
        }
        for service in &file.service {
            let service_name = qualified(package, service.name());
            for method in &service.method {
                self.symbols
                    .insert(qualified(&service_name, method.name()), name.clone());
            }
            self.symbols.insert(service_name.clone(), name.clone());
            self.services.push(service_name);
        }
    }

    fn index_message(&mut self, file: &str, prefix: &str, message: &DescriptorProto) {
        let message_name = qualified(prefix, message.name());
        for field in &message.field {
            self.symbols
                .insert(qualified(&message_name, field.name()), file.to_string());
        }
        for nested in &message.nested_type {
            self.index_message(file, &message_name, nested);
        }
        for enumeration in &message.enum_type {
            self.index_enum(file, &message_name, enumeration);
        }
        self.symbols.insert(message_name, file.to_string());
    }

    fn index_enum(&mut self, file: &str, prefix: &str, enumeration: &EnumDescriptorProto) {
        let enum_name = qualified(prefix, enumeration.name());
        for value in &enumeration.value {
            // Enum values are scoped like C++: beside the enum, not inside it.
            self.symbols
                .insert(qualified(prefix, value.name()), file.to_string());
        }
        self.symbols.insert(enum_name, file.to_string());
    }

    /// `name` and every file it depends on, each once, `name` first.
    fn with_dependencies(&self, name: &str) -> Vec<Vec<u8>> {
        let mut answer = Vec::new();
        let mut seen = HashSet::new();
        let mut pending = vec![name.to_string()];
        while let Some(next) = pending.pop() {
            if !seen.insert(next.clone()) {
                continue;
            }
            // A dependency this server does not describe is left out; the client asks for
            // it by name and gets an in-stream NOT_FOUND.
            if let Some((file, encoded)) = self.files.get(&next) {
                answer.push(encoded.clone());
                pending.extend(file.dependency.iter().rev().cloned());
            }
        }
        answer
    }

    /// The answer to one request.
    pub fn answer(&self, asked: &Asked) -> Answer {
        match asked {
            Asked::FileByFilename(name) => {
                if self.files.contains_key(name) {
                    Answer::Files(self.with_dependencies(name))
                } else {
                    Answer::Error(tonic::Code::NotFound, format!("no file named {name:?}"))
                }
            }
            Asked::FileContainingSymbol(symbol) => {
                // Clients may write a leading dot (a fully qualified name in descriptors).
                let symbol = symbol.strip_prefix('.').unwrap_or(symbol);
                match self.symbols.get(symbol) {
                    Some(file) => Answer::Files(self.with_dependencies(file)),
                    None => {
                        Answer::Error(tonic::Code::NotFound, format!("no symbol named {symbol:?}"))
                    }
                }
            }
            Asked::FileContainingExtension(containing, number) => Answer::Error(
                tonic::Code::NotFound,
                format!("no extension {number} of {containing:?}: this API declares none"),
            ),
            Asked::AllExtensionNumbersOfType(name) => {
                let name = name.strip_prefix('.').unwrap_or(name);
                if self.symbols.contains_key(name) {
                    Answer::ExtensionNumbers(name.to_string())
                } else {
                    Answer::Error(tonic::Code::NotFound, format!("no type named {name:?}"))
                }
            }
            Asked::ListServices => Answer::Services(self.services.clone()),
            Asked::Nothing => Answer::Error(
                tonic::Code::InvalidArgument,
                "the request names no question (message_request is unset)".to_string(),
            ),
        }
    }
}

fn qualified(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_string()
    } else {
        format!("{prefix}.{name}")
    }
}

/// The service for one protocol version: the same code over that version's generated types.
macro_rules! reflection_version {
    ($module:ident, $($pb:ident)::+) => {
        pub mod $module {
            use std::sync::Arc;

            use tokio::sync::mpsc;
            use tokio_stream::StreamExt;
            use tokio_stream::wrappers::ReceiverStream;
            use tonic::{Request, Response, Status, Streaming};

            use super::{Answer, Asked, Descriptors};
            use $($pb)::+ as pb;
            use pb::server_reflection_request::MessageRequest;
            use pb::server_reflection_response::MessageResponse;
            pub use pb::server_reflection_server::ServerReflectionServer;

            #[derive(Debug, Clone)]
            pub struct Reflection {
                pub(super) descriptors: Arc<Descriptors>,
            }

            fn asked(request: &pb::ServerReflectionRequest) -> Asked {
                match &request.message_request {
                    Some(MessageRequest::FileByFilename(name)) => {
                        Asked::FileByFilename(name.clone())
                    }
                    Some(MessageRequest::FileContainingSymbol(symbol)) => {
                        Asked::FileContainingSymbol(symbol.clone())
                    }
                    Some(MessageRequest::FileContainingExtension(extension)) => {
                        Asked::FileContainingExtension(
                            extension.containing_type.clone(),
                            extension.extension_number,
                        )
                    }
                    Some(MessageRequest::AllExtensionNumbersOfType(name)) => {
                        Asked::AllExtensionNumbersOfType(name.clone())
                    }
                    Some(MessageRequest::ListServices(_)) => Asked::ListServices,
                    None => Asked::Nothing,
                }
            }

            fn response(answer: Answer) -> MessageResponse {
                match answer {
                    Answer::Files(files) => {
                        MessageResponse::FileDescriptorResponse(pb::FileDescriptorResponse {
                            file_descriptor_proto: files,
                        })
                    }
                    Answer::Services(names) => {
                        MessageResponse::ListServicesResponse(pb::ListServiceResponse {
                            service: names
                                .into_iter()
                                .map(|name| pb::ServiceResponse { name })
                                .collect(),
                        })
                    }
                    Answer::ExtensionNumbers(base_type_name) => {
                        MessageResponse::AllExtensionNumbersResponse(
                            pb::ExtensionNumberResponse {
                                base_type_name,
                                extension_number: Vec::new(),
                            },
                        )
                    }
                    Answer::Error(code, error_message) => {
                        MessageResponse::ErrorResponse(pb::ErrorResponse {
                            error_code: code as i32,
                            error_message,
                        })
                    }
                }
            }

            #[tonic::async_trait]
            impl pb::server_reflection_server::ServerReflection for Reflection {
                type ServerReflectionInfoStream =
                    ReceiverStream<Result<pb::ServerReflectionResponse, Status>>;

                async fn server_reflection_info(
                    &self,
                    request: Request<Streaming<pb::ServerReflectionRequest>>,
                ) -> Result<Response<Self::ServerReflectionInfoStream>, Status> {
                    let mut requests = request.into_inner();
                    let (answers, receiver) = mpsc::channel(4);
                    let descriptors = Arc::clone(&self.descriptors);
                    tokio::spawn(async move {
                        // Until the client closes its side (or breaks the stream): every
                        // request gets an answer, a failed one an ErrorResponse.
                        while let Some(Ok(request)) = requests.next().await {
                            let answer = descriptors.answer(&asked(&request));
                            let reply = pb::ServerReflectionResponse {
                                valid_host: request.host.clone(),
                                original_request: Some(request),
                                message_response: Some(response(answer)),
                            };
                            if answers.send(Ok(reply)).await.is_err() {
                                return;
                            }
                        }
                    });
                    Ok(Response::new(ReceiverStream::new(receiver)))
                }
            }

            /// The tonic service for this version.
            pub fn server(descriptors: Arc<Descriptors>) -> ServerReflectionServer<Reflection> {
                ServerReflectionServer::new(Reflection { descriptors })
            }
        }
    };
}

reflection_version!(v1, tonic_reflection::pb::v1);
reflection_version!(v1alpha, tonic_reflection::pb::v1alpha);

/// The API's descriptors: SceneQuery, health, and both reflection versions.
pub fn api_descriptors() -> Result<Arc<Descriptors>, prost::DecodeError> {
    Descriptors::new(&[
        crate::proto::FILE_DESCRIPTOR_SET,
        tonic_health::pb::FILE_DESCRIPTOR_SET,
        tonic_reflection::pb::v1::FILE_DESCRIPTOR_SET,
        tonic_reflection::pb::v1alpha::FILE_DESCRIPTOR_SET,
    ])
    .map(Arc::new)
}
