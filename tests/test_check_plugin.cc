// spml check-plugin (issue #25): every in-tree library passes (CheckPluginInTree, a script),
// and each deliberately broken plugin is refused with exit 1, the clause it breaks named.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <regex>
#include <string>

#include "spml/check_plugin.h"
#include "test_util.h"

namespace {

using spml::test::run;

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }
bool contains(const std::vector<std::string>& v, const std::string& x) { return std::find(v.begin(), v.end(), x) != v.end(); }

std::string broken(const std::string& name) { return std::string(SPML_BROKEN_DIR) + "/" + name + ".so"; }

spml::test::RunResult check(const std::string& file) { return run(spml::test::spml_bin() + " check-plugin " + file); }

// The FAIL lines of an output, one per failed clause: "FAIL  <plugin>  <clause>: ...".
std::vector<std::string> failed_clauses(const std::string& output) {
  std::vector<std::string> out;
  const std::regex line("FAIL  (\\S+)  ([a-z-]+)");
  for (auto it = std::sregex_iterator(output.begin(), output.end(), line); it != std::sregex_iterator(); ++it)
    out.push_back((*it)[1].str() + " " + (*it)[2].str());
  return out;
}

void expect_only_failure(const std::string& fixture, const std::string& clause) {
  const auto r = check(broken(fixture));
  SCOPED_TRACE(r.output);
  std::printf("%s:\n", fixture.c_str());
  for (const auto& c : failed_clauses(r.output)) {
    const auto at = r.output.find("FAIL  " + c.substr(0, c.find(' ')) + "  " + c.substr(c.find(' ') + 1));
    std::printf("  %s\n", r.output.substr(at, r.output.find('\n', at) - at).c_str());
  }
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(has(r.output, "spml: error: check-plugin: 1 of "));
  const auto failed = failed_clauses(r.output);
  ASSERT_EQ(failed.size(), 1u);
  EXPECT_TRUE(has(failed[0], clause));
}

TEST(CheckPlugin, PassesTheUnbrokenFixtures) {
  for (const char* f : {"learner_none", "force_none"}) {
    const auto r = check(broken(f));
    EXPECT_EQ(r.exit_code, 0) << r.output;
    EXPECT_TRUE(failed_clauses(r.output).empty()) << r.output;
    EXPECT_TRUE(has(r.output, "0 failed"));
  }
}

TEST(CheckPlugin, RefusesALearnerClaimingDeterminismThatDiffersBetweenFits) {
  expect_only_failure("learner_deterministic", "SmallRidge deterministic");
}
TEST(CheckPlugin, RefusesNegativeVariances) { expect_only_failure("learner_variance", "SmallRidge variance-positive"); }
TEST(CheckPlugin, RefusesOutputsLeftUnwritten) { expect_only_failure("learner_unwritten", "SmallRidge outputs-written"); }
TEST(CheckPlugin, RefusesADefaultOutsideItsBounds) {
  expect_only_failure("learner_default", "SmallRidge key-table");
  EXPECT_TRUE(has(check(broken("learner_default")).output, "key 'lambda': default '5' is outside [0, 1]"));
}
TEST(CheckPlugin, RefusesARegressorThatDoesNotReproduceTheForce) {
  expect_only_failure("force_regressor", "broken_viscous regressor");
}
TEST(CheckPlugin, RefusesAWriteConfigThatDoesNotRecreateThePlugin) {
  expect_only_failure("force_write_config", "broken_viscous write-config");
}

// ABI revision 1: a learner flagged PROGRESS whose fraction goes back fails `progress`,
// naming both fractions; the unbroken fixture (flagged too) passes it.
TEST(CheckPlugin, RefusesProgressThatGoesBack) {
  expect_only_failure("learner_progress_back", "SmallRidge progress");
  EXPECT_TRUE(has(check(broken("learner_progress_back")).output, "the fraction went back from 0.6 to 0.3"));
  const auto good = check(broken("learner_none"));
  EXPECT_TRUE(has(good.output, "PASS  SmallRidge  progress: ")) << good.output;
  EXPECT_TRUE(has(good.output, "never back; predictions identical to fit's")) << good.output;
}

TEST(CheckPlugin, RefusesALearnerThatWritesIntoItsInputs) {
  expect_only_failure("learner_mutate", "SmallRidge inputs-untouched");
  EXPECT_TRUE(has(check(broken("learner_mutate")).output, "fit wrote into its inputs: x[0] was "));
}
TEST(CheckPlugin, RefusesAForcePluginThatWritesAnotherJointsDof) {
  expect_only_failure("force_other_dof", "broken_viscous own-dofs");
  EXPECT_TRUE(has(check(broken("force_other_dof")).output, "attached to joint slide (dof 1) only, compute changed dof 0 (joint hinge)"));
}

// --set is checked before any clause runs: a key no plugin has (a typo) and a value the key
// refuses are usage errors (exit 2) naming key and value, not a failure of the plugin.
TEST(CheckPlugin, SetWithAnUnknownKeyOrABadValueIsAUsageError) {
  const std::string spml = spml::test::spml_bin() + " check-plugin ";
  const auto typo = run(spml + "--set lamda=0.1 " + broken("learner_none"));
  EXPECT_EQ(typo.exit_code, 2) << typo.output;
  EXPECT_TRUE(has(typo.output, "spml: error: --set: lamda=0.1: no plugin in this library has the key 'lamda' (SmallRidge: lambda)"))
      << typo.output;
  EXPECT_FALSE(has(typo.output, "FAIL")) << typo.output;
  const auto range = run(spml + "--set lambda=5 " + broken("learner_none") + " " + broken("force_none"));
  EXPECT_EQ(range.exit_code, 2) << range.output;
  EXPECT_TRUE(has(range.output, "--set: lambda=5: SmallRidge's key 'lambda': '5' is outside [0, 1]")) << range.output;
  const auto text = run(spml + "--set fv=abc " + broken("learner_none") + " " + broken("force_none"));
  EXPECT_EQ(text.exit_code, 2) << text.output;
  EXPECT_TRUE(has(text.output, "--set: fv=abc: broken_viscous's key 'fv': 'abc' is not a comma-separated list of finite numbers"))
      << text.output;
  const auto fine = run(spml + "--set lambda=0.5 " + broken("learner_none") + " " + broken("force_none"));
  EXPECT_EQ(fine.exit_code, 0) << fine.output;   // a key only one of the libraries has is fine
}

// Once the force is not finite, the clauses that compare forces say so instead of reporting
// "difference nan, allowed nan". The fixture is NaN only where |q| > 1.5: the states reach 3.
TEST(CheckPlugin, RefusesANanForceFarOutAndSkipsTheComparisons) {
  expect_only_failure("force_nan_far", "broken_viscous finite-force");
  const auto r = check(broken("force_nan_far"));
  EXPECT_TRUE(has(r.output, "FAIL  broken_viscous  finite-force: force nan on dof")) << r.output;
  EXPECT_TRUE(has(r.output, "SKIP  broken_viscous  no-hidden-state: skipped: the force is not finite (finite-force)")) << r.output;
  EXPECT_TRUE(has(r.output, "SKIP  broken_viscous  params-roundtrip: skipped: the force is not finite (finite-force)")) << r.output;
  EXPECT_FALSE(has(r.output, "difference nan")) << r.output;
}

// write_config is also checked on an instance created with every key drawn away from its
// default: words that leave out `gain` recreate it only while gain is 1.
TEST(CheckPlugin, RefusesAWriteConfigThatDropsAKey) {
  expect_only_failure("force_drop_key", "broken_viscous write-config");
  EXPECT_TRUE(has(check(broken("force_drop_key")).output, "write-config: created with every key drawn (")) << "";
}

// A regressor 10 % off only where |qd| > 2.5: the speeds reach 10 (log-uniform from 1e-3).
TEST(CheckPlugin, RefusesARegressorWrongOnlyAtHighSpeed) {
  expect_only_failure("force_regressor_fast", "broken_viscous regressor");
}

// A learner NaN only where |x0| > 3 (training reaches 2, the query 4), or only on queries of
// more than 20 rows (the query has 200).
TEST(CheckPlugin, RefusesALearnerNanOnlyFarOutOrOnALongQuery) {
  expect_only_failure("learner_nan_far", "SmallRidge outputs-written");
  expect_only_failure("learner_nan_many", "SmallRidge outputs-written");
  EXPECT_TRUE(has(check(broken("learner_nan_many")).output, "400 of 400 means unwritten or non-finite"));
}

// Hidden state that appears only after 200 compute calls: no-hidden-state repeats its states
// after 500 calls.
TEST(CheckPlugin, RefusesHiddenStateThatAppearsLate) {
  const auto r = check(broken("force_hidden_late"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(failed_clauses(r.output), "broken_viscous no-hidden-state")) << r.output;
  EXPECT_TRUE(has(r.output, "without advance (hidden state): dof 0: after 500 calls")) << r.output;
}

// Instances that share their gain through a global (every create overwrites it) while the
// library flags them SPML_FORCE_INDEPENDENT (ABI revision 1): right while one instance lives,
// wrong for diagnose's threads, which walk several at once.
TEST(CheckPlugin, RefusesInstancesThatShareStateWhileFlaggedIndependent) {
  expect_only_failure("force_shared", "broken_viscous independent");
  EXPECT_TRUE(has(check(broken("force_shared")).output, "stepped in turn with the other")) << check(broken("force_shared")).output;
  // The same global with the flag declined (effect_base.h: kIndependent = false) breaks nothing.
  const auto declined = check(broken("force_shared_declared"));
  EXPECT_EQ(declined.exit_code, 0) << declined.output;
  EXPECT_TRUE(has(declined.output, "SKIP  broken_viscous  independent: not flagged")) << declined.output;
}

// Hidden state shows in every clause that calls compute twice; the one it breaks is named.
TEST(CheckPlugin, RefusesHiddenStateInAPluginDeclaringNone) {
  const auto r = check(broken("force_hidden_state"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(failed_clauses(r.output), "broken_viscous no-hidden-state")) << r.output;
  const auto at = r.output.find("FAIL  broken_viscous  no-hidden-state");
  std::printf("force_hidden_state:\n  %s\n", r.output.substr(at, r.output.find('\n', at) - at).c_str());
}

TEST(CheckPlugin, RefusesLibrariesThatAreNoPluginOrSpeakAnotherAbi) {
  const std::string dir = SPML_BROKEN_DIR;
  const auto wrong = check(dir + "/../test-learners/wrong_abi_learner.so");
  EXPECT_EQ(wrong.exit_code, 1);
  EXPECT_TRUE(has(wrong.output, "FAIL  (library)  abi-version"));
  EXPECT_TRUE(has(wrong.output, "learner ABI version"));
  const auto none = check(dir + "/../test-learners/not_a_learner.so");
  EXPECT_EQ(none.exit_code, 1);
  EXPECT_TRUE(has(none.output, "FAIL  (library)  abi-version"));
}

// A plugin that crashes fails the clause it crashed in; the checker goes on with the next
// library (each is checked in a child process) and --json stays one document.
TEST(CheckPlugin, ACrashFailsItsClauseAndTheNextLibraryIsChecked) {
  const auto r = run(spml::test::spml_bin() + " check-plugin " + broken("learner_crash") + " " + broken("force_none"));
  SCOPED_TRACE(r.output);
  EXPECT_EQ(r.exit_code, 1);
  // Under the sanitizers UBSan stops the child at the null store (an exit, not a signal).
  EXPECT_TRUE(has(r.output, "FAIL  SmallRidge  deterministic: the plugin crashed (signal 11)") ||
              has(r.output, "FAIL  SmallRidge  deterministic: the process exited with status"));
  EXPECT_TRUE(has(r.output, "2 libraries, "));
  EXPECT_TRUE(has(r.output, "spml: error: check-plugin: 1 of "));
  const auto j = run(spml::test::spml_bin() + " check-plugin --json " + broken("learner_crash"));
  // stdout and stderr come together here: the document starts at its first key (a sanitizer's
  // report of the crash may come before it).
  const auto from = j.output.find("{\n  \"clauses\"");
  ASSERT_NE(from, std::string::npos) << j.output;
  const auto doc = nlohmann::json::parse(j.output.substr(from, j.output.rfind('}') + 1 - from));
  EXPECT_EQ(doc["failed"], 1);
}

// A child that ends before reporting every clause fails the clause it was in, even when it
// ends with status 0 (exit(0) inside fit once passed as "passed (kind unknown, 0 s)").
TEST(CheckPlugin, ALearnerThatExitsInsideFitFailsThatClause) {
  const auto r = check(broken("learner_exit"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(has(r.output, "FAIL  SmallRidge  fit: the process exited with status 0 before the clause finished")) << r.output;
  EXPECT_TRUE(has(r.output, "spml: error: check-plugin: 1 of ")) << r.output;
}

// A plugin that never returns is stopped at --timeout (per plugin) and fails the clause it
// was in; the next library is still checked.
TEST(CheckPlugin, AHangingLearnerIsStoppedAtTheTimeLimit) {
  const auto r = run(spml::test::spml_bin() + " check-plugin --timeout 1 " + broken("learner_hang") + " " + broken("force_none"));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(has(r.output, "FAIL  SmallRidge  fit: did not finish within the time limit of 1 s per plugin (--timeout)")) << r.output;
  EXPECT_TRUE(has(r.output, "2 libraries, ")) << r.output;
  EXPECT_TRUE(has(r.output, "spml: error: check-plugin: 1 of ")) << r.output;
  const auto zero = run(spml::test::spml_bin() + " check-plugin --timeout 0 " + broken("learner_none"));
  EXPECT_EQ(zero.exit_code, 2) << zero.output;
  EXPECT_TRUE(has(zero.output, "spml: error: --timeout: '0' is outside (0, 1e+06]")) << zero.output;
}

// --set is repeatable (one KEY=VALUE each); the same key twice is a usage error.
TEST(CheckPlugin, SetIsRepeatableAndADuplicateKeyIsAUsageError) {
  const std::string spml = spml::test::spml_bin() + " check-plugin ";
  const auto two = run(spml + "--set lambda=0.3 --set fv=0.2 " + broken("learner_none") + " " + broken("force_none"));
  EXPECT_EQ(two.exit_code, 0) << two.output;
  EXPECT_TRUE(has(two.output, "with fv=0.2 ")) << two.output;   // the force plugin was created with it
  const auto dup = run(spml + "--set lambda=0.3 --set lambda=0.2 " + broken("learner_none"));
  EXPECT_EQ(dup.exit_code, 2) << dup.output;
  EXPECT_TRUE(has(dup.output, "spml: error: --set: key 'lambda' given twice (lambda=0.3, lambda=0.2)")) << dup.output;
}

// What a plugin prints goes to stderr: stdout holds the --json document alone.
TEST(CheckPlugin, PluginOutputDoesNotCorruptTheJsonDocument) {
  const auto r = run("( " + spml::test::spml_bin() + " check-plugin --json " + broken("learner_stdout") + " 2>/dev/null )");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  const auto doc = nlohmann::json::parse(r.output, nullptr, false);
  ASSERT_FALSE(doc.is_discarded()) << r.output;
  EXPECT_EQ(doc["failed"], 0);
  const auto both = run(spml::test::spml_bin() + " check-plugin " + broken("learner_stdout"));
  EXPECT_TRUE(has(both.output, "fitting 40 rows")) << both.output;   // still shown, on stderr
}

TEST(CheckPlugin, JsonCountsTheFailures) {
  const auto r = run(spml::test::spml_bin() + " check-plugin --json " + broken("learner_variance") + " " + broken("force_none") +
                     "");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(has(r.output, "spml: error: check-plugin: 1 of ")) << r.output;
  const auto j = nlohmann::json::parse(r.output.substr(0, r.output.rfind('}') + 1));   // then stderr's error line
  EXPECT_EQ(j["failed"], 1);
  ASSERT_EQ(j["libraries"].size(), 2u);
  EXPECT_EQ(j["libraries"][0]["kind"], "learner");
  EXPECT_EQ(j["libraries"][0]["passed"], false);
  EXPECT_EQ(j["libraries"][1]["kind"], "force plugin");
  EXPECT_EQ(j["libraries"][1]["passed"], true);
}

// The library API gives the same verdicts as the command.
TEST(CheckPlugin, LibraryApiReportsEveryClause) {
  const auto r = spml::check::check_library(broken("force_none"));
  EXPECT_TRUE(r.passed());
  EXPECT_EQ(r.kind, "force plugin");
  std::vector<std::string> names;
  for (const auto& c : r.clauses) names.push_back(c.name);
  for (const char* clause : {"abi-version", "names", "shape-params", "callbacks", "key-table", "create", "finite-force",
                             "no-hidden-state", "own-dofs", "regressor", "params-roundtrip", "write-config", "reset",
                             "independent"})
    EXPECT_TRUE(contains(names, clause)) << clause;
}

}  // namespace
