// JSON files handdb reads or writes are checked against the schemas in schemas/, which are
// embedded in the binary at build time (cmake/EmbedFiles.cmake), so the tool needs no files
// beside it. The validator implements the JSON Schema 2020-12 subset our schemas use (type,
// properties, required, additionalProperties, items, prefixItems, min/maxItems, minimum,
// maximum, exclusiveMinimum/Maximum, enum, const, pattern, minLength, $ref to #/$defs, oneOf,
// anyOf, allOf); an unsupported keyword in a schema is a programming error (THROW_CHECK).
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "base/status.h"

namespace handdb {

// The embedded schema text for e.g. "manifest.schema.json"; empty if unknown.
std::string_view EmbeddedSchema(std::string_view schema_name);

// kSchemaViolation with "<what>: <json pointer>: <problem> (value: <raw>)" for the first problem.
Status ValidateJson(const nlohmann::json& doc,
                    std::string_view schema_name,
                    const std::string& what);

// The same against a schema given as JSON (tests, user-supplied schemas); "$ref": "#/..." resolves
// inside `schema`, "name.schema.json#/..." in an embedded schema.
Status ValidateJsonWithSchema(const nlohmann::json& doc,
                              const nlohmann::json& schema,
                              const std::string& what);

// Reads and parses a JSON file, then validates it (skipped when schema_name is empty).
// Errors: kNotFound, kIoError, kBadJson ("<path>: line L, column C: ..."), kSchemaViolation.
Result<nlohmann::json> ReadJsonFile(const std::filesystem::path& path,
                                    std::string_view schema_name);

// Serialises with 2-space indent + trailing newline (stable bytes) and writes atomically.
Status WriteJsonFileAtomic(const std::filesystem::path& path, const nlohmann::json& doc);

}  // namespace handdb
