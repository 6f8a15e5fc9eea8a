#include "base/json_schema.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <stdexcept>

#include "base/atomic_file.h"
#include "base/json_number.h"
#include "base/testing.h"

namespace handdb {
namespace {

using testing::TempDir;

using nlohmann::json;

const json& PersonSchema() {
  static const json schema = json::parse(R"({
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "required": ["name", "age", "joints"],
    "additionalProperties": false,
    "properties": {
      "name": {"type": "string", "minLength": 2, "maxLength": 8, "pattern": "^[a-z][a-z0-9-]*$"},
      "age": {"type": "integer", "minimum": 0, "exclusiveMaximum": 150},
      "score": {"type": "number", "exclusiveMinimum": 0, "maximum": 1},
      "joints": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
      "pair": {"type": "array", "prefixItems": [{"type": "string"}, {"type": "integer"}], "items": false},
      "kind": {"enum": ["a", "b"]},
      "format": {"const": "handdb-plan"},
      "tags": {"type": "array", "uniqueItems": true},
      "dir": {"$ref": "#/$defs/unit_vec"},
      "either": {"oneOf": [{"type": "integer"}, {"type": "string"}]},
      "any": {"anyOf": [{"type": "integer", "minimum": 10}, {"type": "null"}]},
      "all": {"allOf": [{"type": "integer"}, {"minimum": 5}]},
      "nullable": {"type": ["string", "null"]},
      "extra": {"type": "object", "additionalProperties": {"type": "integer"}}
    },
    "$defs": {"unit_vec": {"type": "array", "items": {"type": "number", "minimum": -1, "maximum": 1},
                           "minItems": 3, "maxItems": 3}}
  })");
  return schema;
}

json Good() { return json::parse(R"({"name": "fist", "age": 3, "joints": [0.1, 0.2, 0.3]})"); }

Status Check(const json& doc) { return ValidateJsonWithSchema(doc, PersonSchema(), "doc.json"); }

TEST(JsonSchema, AcceptsValid) {
  json doc = Good();
  doc["score"] = 0.5;
  doc["pair"] = {"x", 1};
  doc["kind"] = "b";
  doc["format"] = "handdb-plan";
  doc["tags"] = {1, 2, "1"};
  doc["dir"] = {0, 0, 1};
  doc["either"] = "s";
  doc["any"] = nullptr;
  doc["all"] = 7;
  doc["nullable"] = nullptr;
  doc["extra"] = {{"a", 1}, {"b", 2}};
  Status s = Check(doc);
  EXPECT_TRUE(s.ok()) << s.message();
  // An integer-valued float counts as an integer, as the spec says.
  doc["age"] = 3.0;
  EXPECT_TRUE(Check(doc).ok());
}

struct Case {
  const char* patch;    // JSON merged into Good()
  const char* pointer;  // expected JSON pointer in the message
  const char* problem;  // expected substring of the message
};

class JsonSchemaRejects : public ::testing::TestWithParam<Case> {};

TEST_P(JsonSchemaRejects, WithPointerAndProblem) {
  const Case& c = GetParam();
  json doc = Good();
  doc.merge_patch(json::parse(c.patch));
  Status s = Check(doc);
  ASSERT_FALSE(s.ok()) << c.patch;
  EXPECT_EQ(s.code(), StatusCode::kSchemaViolation);
  EXPECT_EQ(s.message().rfind(std::string("doc.json: ") + c.pointer + ": ", 0), 0u) << s.message();
  EXPECT_NE(s.message().find(c.problem), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("(value: "), std::string::npos) << s.message();
}

INSTANTIATE_TEST_SUITE_P(
    Keywords,
    JsonSchemaRejects,
    ::testing::Values(Case{R"({"name": 5})", "/name", "expected string, got integer"},
                      Case{R"({"name": "x"})", "/name", "minLength"},
                      Case{R"({"name": "abcdefghij"})", "/name", "maxLength"},
                      Case{R"({"name": "Fist"})", "/name", "pattern"},
                      Case{R"({"age": 2.5})", "/age", "expected integer"},
                      Case{R"({"age": -1})", "/age", "must be >= 0"},
                      Case{R"({"age": 150})", "/age", "must be < 150"},
                      Case{R"({"score": 0})", "/score", "must be > 0"},
                      Case{R"({"score": 1.5})", "/score", "must be <= 1"},
                      Case{R"({"joints": [1, 2]})", "/joints", "minItems is 3"},
                      Case{R"({"joints": [1, 2, 3, 4]})", "/joints", "maxItems is 3"},
                      Case{R"({"joints": [1, "2", 3]})", "/joints/1", "expected number"},
                      Case{R"({"pair": [1, 1]})", "/pair/0", "expected string"},
                      Case{R"({"pair": ["a", 1, 2]})", "/pair/2", "not allowed"},
                      Case{R"({"kind": "c"})", "/kind", "must be one of"},
                      Case{R"({"format": "plan"})", "/format", "must equal"},
                      Case{R"({"tags": [1, 2, 1.0]})", "/tags/2", "duplicate of item 0"},
                      Case{R"({"dir": [0, 2, 0]})", "/dir/1", "must be <= 1"},
                      Case{R"({"either": 1.5})", "/either", "none of oneOf"},
                      Case{R"({"any": 3})", "/any", "none of anyOf"},
                      Case{R"({"all": 3})", "/all", "must be >= 5"},
                      Case{R"({"nullable": 1})", "/nullable", "expected string or null"},
                      Case{R"({"extra": {"a": "x"}})", "/extra/a", "expected integer"},
                      Case{R"({"surprise": 1})", "/surprise", "unknown property 'surprise'"},
                      Case{R"({"age": null})", "/", "missing required property 'age'"}));

TEST(JsonSchema, OneOfRejectsTwoMatches) {
  json schema = json::parse(R"({"oneOf": [{"type": "number"}, {"type": "integer"}]})");
  EXPECT_TRUE(ValidateJsonWithSchema(1.5, schema, "x").ok());
  Status s = ValidateJsonWithSchema(1, schema, "x");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("matches 2 branches"), std::string::npos) << s.message();
}

TEST(JsonSchema, UnsupportedKeywordIsAProgrammingError) {
  json schema = json::parse(R"({"type": "object", "properties": {"a": {"multipleOf": 2}}})");
  EXPECT_THROW((void)ValidateJsonWithSchema(json::object(), schema, "x"), std::logic_error);
}

TEST(JsonSchema, UnknownEmbeddedSchemaIsAProgrammingError) {
  EXPECT_TRUE(EmbeddedSchema("no-such.schema.json").empty());
  EXPECT_THROW((void)ValidateJson(json::object(), "no-such.schema.json", "x"), std::logic_error);
}

TEST(JsonSchema, EveryEmbeddedSchemaLoads) {
  // Each shipped schema parses and uses only supported keywords (validation of some document
  // forces the load; the result itself does not matter here).
  for (const char* name : {"manifest.schema.json",
                           "hand_model.schema.json",
                           "shapes.schema.json",
                           "render_sidecar.schema.json",
                           "config.schema.json",
                           "render_plan.schema.json",
                           "testset_config.schema.json",
                           "testset_plan.schema.json",
                           "testset.schema.json"}) {
    ASSERT_FALSE(EmbeddedSchema(name).empty()) << name;
    EXPECT_NO_THROW((void)ValidateJson(json::object(), name, name)) << name;
  }
}

TEST(JsonSchema, ReadJsonFileReportsLineAndColumn) {
  auto dir = TempDir("read");
  ASSERT_TRUE(WriteFileAtomic(dir / "bad.json", "{\n  \"a\": 1,\n  \"b\": tru\n}\n").ok());
  auto r = ReadJsonFile(dir / "bad.json", "");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kBadJson);
  EXPECT_NE(r.status().message().find("bad.json: line 3, column"), std::string::npos)
      << r.status().message();

  auto missing = ReadJsonFile(dir / "missing.json", "");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
}

// Found by the manifest fuzzer: nlohmann reports a number beyond a double's range as out_of_range,
// not parse_error; it escaped ParseJsonText and terminated the process.
TEST(JsonSchema, NumberOverflowIsBadJsonNotACrash) {
  auto r = ParseJsonText("{\"views\": 81335e719}", "m.json");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kBadJson);
  EXPECT_EQ(r.status().message(), "m.json: number overflow parsing '81335e719'");
}

// {"seed": 1, "seed": 2} is refused (nlohmann alone keeps the last without a word).
TEST(JsonSchema, DuplicateKeysAreRefused) {
  auto dup = ParseJsonText(R"({"a": {"seed": 1, "x": [{"k": 0}, {"k": 1}], "seed": 2}})", "c.json");
  ASSERT_FALSE(dup.ok());
  EXPECT_EQ(dup.status().code(), StatusCode::kBadJson);
  EXPECT_EQ(dup.status().message(),
            "c.json: key \"seed\" appears twice in one object (which one is meant?)");
  // Equal keys in different objects (siblings, nesting) are fine.
  auto ok = ParseJsonText(R"({"k": {"k": 1}, "x": [{"k": 0}, {"k": 1}]})", "c.json");
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  EXPECT_EQ((*ok)["x"][1]["k"], 1);
}

// 100,000 nested '[' would overflow the stack; refused before parsing, with the byte.
TEST(JsonSchema, DepthIsBoundedBeforeParsing) {
  EXPECT_TRUE(CheckJsonDepth(std::string(64, '[') + std::string(64, ']'), "x").ok());
  const Status s = CheckJsonDepth(std::string(65, '[') + std::string(65, ']'), "x");
  EXPECT_EQ(s.code(), StatusCode::kBadJson);
  EXPECT_EQ(s.message(), "x: JSON nested deeper than 64 levels at byte 64");
  // Brackets inside strings (escaped quotes included) do not count.
  EXPECT_TRUE(CheckJsonDepth("[\"\\\"" + std::string(100, '[') + "\"]", "x").ok());
  EXPECT_FALSE(CheckJsonDepth("{\"a\": [{\"b\": [[]]}]}", "x", 4).ok());
  EXPECT_TRUE(CheckJsonDepth("{\"a\": [{\"b\": [[]]}]}", "x", 5).ok());

  auto dir = TempDir("deep");
  ASSERT_TRUE(WriteFileAtomic(dir / "deep.json", std::string(100000, '[')).ok());
  auto r = ReadJsonFile(dir / "deep.json", "config.schema.json");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().message(),
            (dir / "deep.json").string() + ": JSON nested deeper than 64 levels at byte 64");
}

TEST(JsonSchema, ReadJsonFileBoundsTheSizeByKind) {
  auto dir = TempDir("big");
  const std::string big = "[" + std::string(MaxJsonFileBytes("config.schema.json"), ' ') + "]";
  ASSERT_TRUE(WriteFileAtomic(dir / "big.json", big).ok());
  auto r = ReadJsonFile(dir / "big.json", "config.schema.json");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("more than the 1048576 allowed"), std::string::npos)
      << r.status().message();
  EXPECT_TRUE(ReadJsonFile(dir / "big.json", "").ok());  // plans may be larger
}

TEST(JsonSchema, WriteThenReadRoundTripsWithStableBytes) {
  auto dir = TempDir("write");
  json doc = Good();
  doc["pi"] = 3.141592653589793;
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "a.json", doc).ok());
  ASSERT_TRUE(WriteJsonFileAtomic(dir / "b.json", doc).ok());
  auto a = ReadFileToString(dir / "a.json");
  auto b = ReadFileToString(dir / "b.json");
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(*a, *b);
  EXPECT_EQ(a->back(), '\n');
  auto back = ReadJsonFile(dir / "a.json", "");
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(*back, doc);
}

// nlohmann stops at a NUL byte: "{...}\0junk" parsed as "{...}" with the junk ignored.
TEST(JsonSchema, NulByteIsRefusedWithItsOffset) {
  const std::string text = std::string("{\"a\": 1}\0junk", 13);
  auto r = ParseJsonText(text, "x.json");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kBadJson);
  EXPECT_EQ(r.status().message(), "x.json: NUL byte at offset 8 (not allowed in JSON text)");
  EXPECT_FALSE(CheckJsonText(std::string("[\"a\0\"]", 6), "y").ok());
  EXPECT_TRUE(CheckJsonText("{\"a\": \"\\u0000\"}", "z").ok());  // an escaped NUL is JSON
}

// get<uint32_t>() cut 2^32 + 12 to 12; 2^64 + 12 parses as a double.
TEST(JsonNumber, IntegersAreRangeCheckedBeforeNarrowing) {
  EXPECT_EQ(*JsonInteger<uint32_t>(json(4294967295ull), "f", "rolls"), 4294967295u);
  auto over = JsonInteger<uint32_t>(json(4294967308ull), "f", "rolls");
  ASSERT_FALSE(over.ok());
  EXPECT_EQ(over.status().code(), StatusCode::kOutOfRange);
  EXPECT_EQ(over.status().message(), "f: rolls is 4294967308, not an integer in 0..4294967295");
  auto huge = JsonInteger<uint64_t>(json::parse("18446744073709551628"), "f", "seed");
  ASSERT_FALSE(huge.ok());
  EXPECT_EQ(huge.status().message(),
            "f: seed is 1.8446744073709552e+19, not an integer in 0..18446744073709551615");
  EXPECT_FALSE(JsonInteger<uint32_t>(json(-1), "f", "n").ok());
  EXPECT_FALSE(JsonInteger<int>(json(2.0), "f", "n").ok());  // a float, even an integral one
  EXPECT_EQ(*JsonInteger<int>(json(-5), "f", "n"), -5);
  EXPECT_FALSE(JsonInteger<int>(json(int64_t{1} << 31), "f", "n").ok());
  EXPECT_EQ(*JsonInteger<uint64_t>(json(18446744073709551615ull), "f", "n"),
            18446744073709551615ull);
  EXPECT_THROW(JsonIntegerOrThrow<uint16_t>(json(65536), "n"), JsonRangeError);
  EXPECT_EQ(JsonIntegerOrThrow<uint16_t>(json(65535), "n"), 65535);
}

}  // namespace
}  // namespace handdb
