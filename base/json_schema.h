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

// Limits on every JSON document handdb reads (docs/conventions.md, "JSON limits"): our own files
// nest 6 levels deep at most, so anything past kMaxJsonDepth is refused before it is parsed (deep
// nesting would overflow the stack in the recursive schema check and in dump()).
constexpr int kMaxJsonDepth = 64;

// The largest file ReadJsonFile accepts for a kind of file, by its schema name: 1 MiB for configs,
// sidecars and hand models, 64 MiB for manifests, 256 MiB for plans, test sets and the rest (""
// included). Checked with stat() before the file is read.
uint64_t MaxJsonFileBytes(std::string_view schema_name);

// kBadJson "<what>: JSON nested deeper than <max_depth> levels at byte N" (N 0-based) when arrays
// and objects nest deeper than max_depth. One linear pass that skips strings; no allocation.
Status CheckJsonDepth(std::string_view text,
                      const std::string& what,
                      int max_depth = kMaxJsonDepth);

// CheckJsonDepth, and kBadJson "<what>: NUL byte at offset N (not allowed in JSON text)" for the
// first NUL: nlohmann's parser takes a NUL for the end of the input, so "{...}\0junk" would parse
// as "{...}" with the rest ignored.
Status CheckJsonText(std::string_view text, const std::string& what);

// CheckJsonText, then parse. kBadJson "<what>: line L, column C: <problem>".
Result<nlohmann::json> ParseJsonText(std::string_view text, const std::string& what);

// Reads (at most MaxJsonFileBytes(schema_name) bytes of a regular file), parses (at most
// kMaxJsonDepth levels) and validates a JSON file (skipped when schema_name is empty).
// Errors: kNotFound, kIoError, kBadJson ("<path>: line L, column C: ..."), kSchemaViolation.
Result<nlohmann::json> ReadJsonFile(const std::filesystem::path& path,
                                    std::string_view schema_name);

// Serialises with 2-space indent + trailing newline (stable bytes) and writes atomically.
Status WriteJsonFileAtomic(const std::filesystem::path& path, const nlohmann::json& doc);

}  // namespace handdb
