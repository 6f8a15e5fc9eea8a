#include "generator/pipeline.h"

#include <system_error>
#include <utility>

#include "base/json_schema.h"
#include "generator/plan/plan.h"

namespace handdb {
namespace fs = std::filesystem;

bool GenerateOptions::Check(std::string* error) const {
  auto fail = [error](const std::string& what) {
    if (error) *error = what;
    return false;
  };
  if (config_path.empty()) return fail("no generation config");
  if (db_dir.empty()) return fail("no database directory");
  if (!render.Check()) return fail("bad render options");
  if (!convert.Check()) return fail("bad convert options");
  return true;
}

GeneratePipeline::GeneratePipeline(GenerateOptions options) : options_(std::move(options)) {
  THROW_CHECK(options_.Check());
  if (options_.work_dir.empty()) options_.work_dir = options_.db_dir / "render";
  options_.render.progress = options_.progress;
  options_.convert.progress = options_.progress;
}

void GeneratePipeline::Stage(int k, const char* name) const {
  if (options_.on_stage) options_.on_stage(k, num_stages(), name);
}

Status GeneratePipeline::Plan() {
  Stage(1, "plan");
  const fs::path& config_path = options_.config_path;
  const fs::path plan_file = plan_path();
  auto config = ReadJsonFile(config_path, "config.schema.json");
  if (!config.ok()) return config.status();
  auto plan = MakePlan(*config, config_path);
  if (!plan.ok()) return plan.status();
  std::error_code ec;
  for (const fs::path& dir : {options_.db_dir, options_.work_dir}) {
    fs::create_directories(dir, ec);
    if (ec) return Status(StatusCode::kIoError, dir.string() + ": cannot create: " + ec.message());
    auto lock = DirectoryLock::Acquire(dir);
    if (!lock.ok()) return lock.status();
    locks_.push_back(std::move(lock).value());
  }
  if (fs::exists(plan_file, ec)) {
    auto existing = ReadJsonFile(plan_file, "");
    if (!existing.ok()) return existing.status();
    if (*existing != *plan) {
      return Status(StatusCode::kInvalidArgument,
                    plan_file.string() + ": holds a different plan than " + config_path.string() +
                        " makes; use another --out/--work");
    }
  } else {
    HANDDB_RETURN_IF_ERROR(WritePlanFromConfig(config_path, plan_file));
  }
  planned_ = true;
  return Status::Ok();
}

Status GeneratePipeline::Run(GenerateSummary* summary) {
  THROW_CHECK(planned_);
  const fs::path& db_dir = options_.db_dir;
  const fs::path& work_dir = options_.work_dir;

  Stage(2, "render");
  auto rendered = RenderPlan(plan_path(), work_dir, options_.render);
  if (!rendered.ok()) return rendered.status();
  summary->render = *rendered;

  Stage(3, "convert");
  auto converted = ConvertRenderDir(work_dir, db_dir, options_.convert, &summary->bad);
  if (!converted.ok()) return converted.status();
  summary->convert = *converted;

  // What was written is validated as `handdb validate` would.
  Stage(4, "validate");
  ValidateOptions validate;
  validate.show_progress = options_.progress;
  summary->validation = ValidateDatabase(db_dir, validate);
  if (!summary->validation.ok()) {
    return Status(StatusCode::kSchemaViolation,
                  db_dir.string() + ": validation found " +
                      std::to_string(summary->validation.num_problems()) + " problem(s)");
  }

  if (options_.index_step) {
    Stage(5, "index");
    HANDDB_RETURN_IF_ERROR(options_.index_step(db_dir));
  }
  return Status::Ok();
}

}  // namespace handdb
